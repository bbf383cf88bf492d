"""Units shared by every layer: stamps are integer nanoseconds."""

NS = 1_000_000_000      # nanoseconds per second
