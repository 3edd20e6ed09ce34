"""Errors: bad input (one line naming the source, the field and the value, exit 2) and a run that started
but could not finish (one line, exit 1)."""
from __future__ import annotations


class InputError(ValueError):
    """Bad user input (file, option, recording). The CLI prints it as one line and exits 2.

    >>> str(InputError("models/x.toml", "motor.resistance_ohm", "'0.6 ohm'", "expected a number"))
    "models/x.toml: motor.resistance_ohm = '0.6 ohm': expected a number"
    """

    def __init__(self, source: str, field: str, value: object, problem: str, row: int | None = None):
        self.source, self.field, self.value, self.problem, self.row = source, field, value, problem, row
        where = f"{source}" + (f" row {row}" if row is not None else "")
        if _is_scalar(value):
            value = value.item()
        shown = value if isinstance(value, str) else repr(value)
        if len(shown) > MAX_SHOWN:
            shown = shown[:MAX_SHOWN] + "..."
        super().__init__(one_line(f"{where}: {field} = {shown}: {problem}"))


class RunFailed(RuntimeError):
    """A run that started on valid input but cannot reach a result (a step whose fit failed): the CLI
    prints one line and exits 1, writing nothing."""

    def __init__(self, step: str, status: str, message: str):
        self.step, self.status = step, status
        super().__init__(one_line(f"{step} failed ({status}): {message}"))


def _is_scalar(value: object) -> bool:
    """A numpy scalar (shown as its Python value, 70.0 rather than np.float64(70.0))."""
    return type(value).__module__ == "numpy" and getattr(value, "ndim", None) == 0


MAX_SHOWN = 120  # characters of a bad value shown in a message (a whole CSV row or file is not)


def one_line(text: str) -> str:
    """``text`` with line breaks and other control characters escaped as in Python literals (a line
    feed becomes backslash-n): a message is one line."""
    return "".join(ch if ch.isprintable() else repr(ch)[1:-1] for ch in text)
