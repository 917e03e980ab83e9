"""The one error type of the label readers: names the file, the line when there is one, and why."""

from __future__ import annotations

from pathlib import Path


class LabelError(ValueError):
    """A label file is unknown or malformed."""

    def __init__(self, path: str | Path, message: str, line: int | None = None) -> None:
        self.path = Path(path)
        self.line = line
        self.reason = message
        where = f"{self.path}:{line}" if line is not None else str(self.path)
        super().__init__(f"{where}: {message}")
