"""Units shared by every layer: stamps are integer nanoseconds."""

NS = 1_000_000_000      # nanoseconds per second
# the latest stamp a builtin_interfaces/Time can hold (sec is an int32)
MAX_STAMP_NS = (2**31 - 1) * NS + NS - 1
