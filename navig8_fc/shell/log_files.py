"""The FC's logs as the log-download protocol serves them (navig8_fc.gcs.log_transfer's `LogSource`): every MCAP
file in the directory of the FC's log (its own run's parts and earlier runs'), oldest first. docs/logs.md,
"Downloading logs over MAVLink".

A log still being written is served as it was when listed, whole: navig8-fc's log is sealed (navig8_fc/shell/
mcap_writer.py), so at any moment it ends in the constant provisional end (`PROVISIONAL_END`) and the next write
starts over that end; the bytes before it never change. The listing keeps each file's size; a read below
size - len(PROVISIONAL_END) comes from the file, the rest from the constant. The download is then a whole MCAP file
as of the listing (the stock readers read it), however much the flight writes meanwhile.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import BinaryIO

from navig8_fc.gcs.log_transfer import LogEntry
from navig8_fc.shell.mcap_writer import PROVISIONAL_END


class LogDirectory:
    """`LogSource` over the MCAP files in `directory` (module docstring)."""

    def __init__(self, directory: Path) -> None:
        self.directory = Path(directory)
        self._listed: list[tuple[Path, int, bool]] = []  # path, size, ends in the provisional end
        self._open: tuple[Path, BinaryIO] | None = None

    def list_logs(self) -> list[LogEntry]:
        self.close()
        found: list[tuple[float, str, Path, int]] = []
        try:
            paths = list(self.directory.glob("*.mcap"))
        except OSError:
            paths = []
        for p in paths:
            try:
                st = p.stat()
            except OSError:
                continue  # gone since the glob
            if st.st_size > 0:
                found.append((st.st_mtime, p.name, p, st.st_size))
        found.sort()
        self._listed = [(p, size, _ends_sealed(p, size)) for _t, _n, p, size in found]
        return [LogEntry(int(t), size) for t, _n, _p, size in found]

    def read(self, log_id: int, offset: int, n: int) -> bytes:
        path, size, sealed = self._listed[log_id]
        end = min(offset + n, size)
        if offset >= end:
            return b""
        stable = size - len(PROVISIONAL_END) if sealed else size  # what the writer will not write over
        data = b""
        if offset < stable:
            fh = self._file(path)
            fh.seek(offset)
            data = fh.read(min(end, stable) - offset)
            if len(data) < min(end, stable) - offset:
                return data  # shorter than listed: the caller says so
        if end > stable:
            data += PROVISIONAL_END[max(offset, stable) - stable:end - stable]
        return data

    def _file(self, path: Path) -> BinaryIO:
        if self._open is None or self._open[0] != path:
            self.close()
            self._open = (path, path.open("rb"))
        return self._open[1]

    def close(self) -> None:
        if self._open is not None:
            self._open[1].close()
            self._open = None


def _ends_sealed(path: Path, size: int) -> bool:
    """Whether the file ends in the sealed writer's provisional end (a log being written, or one cut by a crash)."""
    n = len(PROVISIONAL_END)
    if size < n:
        return False
    try:
        with path.open("rb") as fh:
            fh.seek(size - n, os.SEEK_SET)
            return fh.read(n) == PROVISIONAL_END
    except OSError:
        return False


__all__ = ["LogDirectory"]
