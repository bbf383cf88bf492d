"""
Input rate and staleness of a sample stream, as diagnostic_updater's FrequencyStatus does.

Not from the papers: OK, WARN (rate below min_fraction of the nominal rate over a sliding
window) or ERROR (silent for stale_after seconds); the rules are in doc/design/core.md.
"""

from collections import deque
from typing import Optional, Protocol, Union

from tskf_ros.core.units import NS

MAX_RECEIPTS = 100_000
# a diagnostics key value: a count, a measurement or a text
DiagnosticValue = Union[int, float, str]


class RateSettings(Protocol):
    """The fields of a session config that set its input monitor (seconds, fraction)."""

    @property
    def rate_window(self) -> float:
        """Return the window over which the input rate is measured (s)."""

    @property
    def min_rate_fraction(self) -> float:
        """Return the fraction of the nominal rate below which the rate is a WARN (0: off)."""

    @property
    def stale_timeout(self) -> float:
        """Return the silence after which the input is an ERROR (s, 0: off)."""


class InputRate:
    """Receipt times of a stream and the OK / WARN / ERROR verdict on them."""

    def __init__(self, nominal_rate: float, *, window: float, min_fraction: float,
                 stale_after: float) -> None:
        self.nominal_rate = float(nominal_rate)      # samples per second expected
        self.window_ns = int(window * NS)
        self.min_fraction = float(min_fraction)      # 0: no rate check
        self.stale_ns = int(stale_after * NS)        # 0: no staleness check
        self.receipts: deque[int] = deque(maxlen=MAX_RECEIPTS)
        self.first_report_ns: Optional[int] = None

    @classmethod
    def for_config(cls, period: float, config: RateSettings) -> 'InputRate':
        """Build the monitor of a session config (its rate_window, min_rate_fraction, ...)."""
        return cls(1.0 / period, window=config.rate_window,
                   min_fraction=config.min_rate_fraction, stale_after=config.stale_timeout)

    def note(self, now_ns: int) -> None:
        """Count one receipt at now_ns (receiver clock)."""
        self.receipts.append(int(now_ns))

    def rate(self, now_ns: int) -> float:
        """Return the receipts per second over the window ending at now_ns."""
        lo = now_ns - self.window_ns
        while self.receipts and self.receipts[0] <= lo:
            self.receipts.popleft()
        return len(self.receipts) / (self.window_ns / NS) if self.window_ns > 0 else 0.0

    def level(self, now_ns: int) -> tuple[str, str, dict[str, DiagnosticValue]]:
        """Return (level, message or '', values) of the stream at now_ns."""
        now_ns = int(now_ns)
        if self.first_report_ns is None:
            self.first_report_ns = now_ns
        last = self.receipts[-1] if self.receipts else None
        silent = (now_ns - (last if last is not None else self.first_report_ns)) / NS
        rate = self.rate(now_ns)
        values: dict[str, DiagnosticValue] = {'input_rate_hz': rate, 'input_silent_s': silent}
        if self.stale_ns and silent * NS >= self.stale_ns:
            what = 'no input yet' if last is None else 'no input'
            return 'ERROR', f'{what} for {silent:.3g} s (stale_timeout)', values
        # the rate is judged only once a whole window has passed since the first report
        whole = now_ns - self.first_report_ns >= self.window_ns
        if (self.min_fraction > 0 and whole
                and rate < self.min_fraction * self.nominal_rate):
            return 'WARN', (f'input rate {rate:.3g} Hz is below {self.min_fraction:g} of '
                            f'the nominal {self.nominal_rate:.3g} Hz'), values
        return 'OK', '', values


LEVELS = ('OK', 'WARN', 'ERROR')


def worst(level: str, other: str) -> str:
    """Return the more severe of two diagnostics levels."""
    return max(level, other, key=LEVELS.index)


def report_head(rate: InputRate, now_ns: Optional[int], self_restart: str
                ) -> tuple[str, list[str], dict[str, DiagnosticValue]]:
    """
    Begin a session's diagnostics: (level, messages, values) from the input and a restart.

    The input's rate and staleness count when the receiver clock now_ns is given; a
    non-empty self_restart (why the session restarted itself since the last report) is
    an ERROR.
    """
    level = 'OK'
    msgs: list[str] = []
    values: dict[str, DiagnosticValue] = {}
    if now_ns is not None:
        rate_level, why, values = rate.level(now_ns)
        if why:
            level = rate_level
            msgs.append(why)
    if self_restart:
        level = 'ERROR'
        msgs.append(self_restart)
    return level, msgs, values
