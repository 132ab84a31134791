"""The MAVLink log-download protocol (LOG_REQUEST_LIST / LOG_ENTRY, LOG_REQUEST_DATA / LOG_DATA, LOG_REQUEST_END,
LOG_ERASE; https://mavlink.io/en/services/ftp.html's older sibling, common.xml) over the FC's own logs, as PX4's
`MavlinkLogHandler` serves its .ulg files. docs/logs.md, "Downloading logs over MAVLink".

- LOG_REQUEST_LIST (start, end; end 0xFFFF = the last): the logs are listed afresh (`LogSource.list_logs`: ids
  0..n-1, oldest first, each with its time and size) and a LOG_ENTRY goes back for every id in [start, end], with
  num_logs n and last_log_num n-1. No logs: one LOG_ENTRY with id 0, num_logs 0 and size 0 (PX4's answer; MAVSDK
  reports NO_LOGFILES). A range that names no log gets a STATUSTEXT.
- LOG_REQUEST_DATA (id, ofs, count; count 0xFFFFFFFF = to the end): LOG_DATA packets of 90 bytes from ofs up to
  ofs + count or the size the listing reported, whichever comes first; at or past that size one LOG_DATA with
  count 0 (PX4's end of file). A new request replaces the one still being sent (the client asks again for what it
  missed); an id not listed gets a STATUSTEXT and nothing else.
- LOG_REQUEST_END: the requester's transfer stops.
- LOG_ERASE: refused with a STATUSTEXT. PX4 deletes its logs; here they are files of the host the FC runs on,
  which a ground-station message does not delete (the operator does, on the host).

Every reply goes to the requester only, paced per destination by a `ReplyPacer` with MAVFTP's budgets (2.5 KB/s,
the operator's configured station 50 KB/s; at most 4 packets per service poll): docs/security.md, "MAVFTP". The
listing and the data are drawn lazily as the budget refills, so no request makes the FC read or send more than the
budget affords. Pure: the files are read through `LogSource` (the shell's log directory); the caller gives the time.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterator
from dataclasses import dataclass
from typing import Any, Protocol

from navig8_fc.gcs.ftp_pacing import FRAME_OVERHEAD_BYTES, ReplyPacer
from navig8_fc.gcs.params import is_for_us
from navig8_fc.gcs.statustext import StatusTextEncoder

LOG_DATA_LEN = 90  # LOG_DATA.data
READ_BLOCK_BYTES = 64 * LOG_DATA_LEN  # one file read feeds 64 packets
LAST_ID = 0xFFFF  # LOG_REQUEST_LIST.end: the last log
TO_THE_END = 0xFFFFFFFF  # LOG_REQUEST_DATA.count: the rest of the log
LOG_ENTRY_PAYLOAD_BYTES = 14
LOG_DATA_HEADER_BYTES = 7  # id, ofs, count before the data
_LIST, _DATA = 0, 1  # the pacer's keys for a requester's listing and its data (one of each at a time)
_BY_IDS = "ids"  # a pacing key for a requester without a source (in-process callers): its ids


@dataclass(frozen=True)
class LogEntry:
    """One log as listed: its time (Unix s, LOG_ENTRY.time_utc) and size (bytes) at the listing."""

    time_utc_s: int
    size_bytes: int


class LogSource(Protocol):
    """The FC's logs (the shell's log directory)."""

    def list_logs(self) -> list[LogEntry]:
        """The logs now, oldest first (id = position); `read` serves this listing until the next one."""
        ...

    def read(self, log_id: int, offset: int, n: int) -> bytes:
        """Up to n bytes of log `log_id` of the last listing from `offset` (OSError when it cannot be read)."""
        ...


def reply_cost(msg: Any) -> int:
    """The bytes a reply puts on the wire (MAVLink 2 frame, unsigned; the pacer's cost)."""
    if msg.get_type() == "LOG_DATA":
        return FRAME_OVERHEAD_BYTES + LOG_DATA_HEADER_BYTES + int(msg.count)
    if msg.get_type() == "LOG_ENTRY":
        return FRAME_OVERHEAD_BYTES + LOG_ENTRY_PAYLOAD_BYTES
    return FRAME_OVERHEAD_BYTES + 51  # STATUSTEXT


class LogTransfer:
    """The log-download protocol of one component (module docstring)."""

    def __init__(self, mav: Any, sysid: int, compid: int, source: LogSource | None, pacer: ReplyPacer,
                 statustext: StatusTextEncoder) -> None:
        """source None: the FC writes no log (every listing is empty)."""
        self._mav = mav
        self._sysid, self._compid = int(sysid), int(compid)
        self._source = source
        self.pacer = pacer
        self._text = statustext
        self._listing: list[LogEntry] | None = None
        self._errors: list[str] = []  # read errors met while drawing data, told at the next poll

    def handle(self, msg: Any, source: Hashable = None, now_s: float = 0.0) -> list[Any]:
        """What to send now to the sender of `msg` (the rest follows from `poll`)."""
        kind = msg.get_type()
        if not kind.startswith("LOG_") or kind in ("LOG_ENTRY", "LOG_DATA"):
            return []
        if not is_for_us(msg, self._sysid, self._compid):
            return []
        to = (msg.get_srcSystem(), msg.get_srcComponent())
        key = source if source is not None else (_BY_IDS, *to)
        if kind == "LOG_REQUEST_LIST":
            problem = self._list(key, to, int(msg.start), int(msg.end), now_s)
        elif kind == "LOG_REQUEST_DATA":
            problem = self._data(key, to, int(msg.id), int(msg.ofs), int(msg.count), now_s)
        elif kind == "LOG_REQUEST_END":
            self.pacer.add(key, to, now_s, [], iter(()), _DATA)
            problem = None
        elif kind == "LOG_ERASE":
            problem = "LOG_ERASE refused: the logs are files on the FC's host; delete them there"
        else:
            return []
        if problem is not None:
            return self._text.warning(problem)
        return [m for _key, _to, m in self.pacer.take(now_s, only=key)]

    def poll(self, now_s: float) -> list[tuple[Hashable, Any]]:
        """(source, reply) pairs the budgets afford now; source None for a STATUSTEXT to everyone."""
        out: list[tuple[Hashable, Any]] = []
        if self.pacer.pending:
            out = [(None if isinstance(key, tuple) and key[:1] == (_BY_IDS,) else key, m)
                   for key, _to, m in self.pacer.take(now_s)]
        for text in self._errors:
            out += [(None, m) for m in self._text.warning(text)]
        self._errors = []
        return out

    # --- requests ----------------------------------------------------------------------------------------
    def _list(self, key: Hashable, to: tuple[int, int], start: int, end: int, now_s: float) -> str | None:
        logs = self._listing = self._source.list_logs() if self._source is not None else []
        n = len(logs)
        if n == 0:
            self.pacer.add(key, to, now_s, [], iter([self._mav.log_entry_encode(0, 0, 0, 0, 0)]), _LIST)
            return None
        last = n - 1 if end == LAST_ID else min(end, n - 1)
        if start > last:
            return f"LOG_REQUEST_LIST: no log {start}..{end} (logs 0..{n - 1})"
        self.pacer.add(key, to, now_s, [], self._entries(logs, start, last), _LIST)
        return None

    def _entries(self, logs: list[LogEntry], first: int, last: int) -> Iterator[Any]:
        n = len(logs)
        for i in range(first, last + 1):
            e = logs[i]
            yield self._mav.log_entry_encode(i, n, n - 1, int(e.time_utc_s), int(e.size_bytes))

    def _data(self, key: Hashable, to: tuple[int, int], log_id: int, ofs: int, count: int,
              now_s: float) -> str | None:
        if self._listing is None and self._source is not None:
            self._listing = self._source.list_logs()  # data asked for without a listing: list now
        logs = self._listing or []
        if not 0 <= log_id < len(logs):
            return f"LOG_REQUEST_DATA: no log {log_id} (logs 0..{len(logs) - 1})" if logs else \
                "LOG_REQUEST_DATA: no logs"
        size = logs[log_id].size_bytes
        end = size if count == TO_THE_END else min(size, ofs + count)
        if ofs >= end:  # at or past the end: one empty packet, PX4's end of file
            packets: Iterator[Any] = iter([self._mav.log_data_encode(log_id, ofs, 0, [0] * LOG_DATA_LEN)])
        else:
            packets = self._packets(log_id, ofs, end)
        self.pacer.add(key, to, now_s, [], packets, _DATA)
        return None

    def _packets(self, log_id: int, start: int, end: int) -> Iterator[Any]:
        """LOG_DATA from `start` to `end`, read a block at a time as the pacer draws them."""
        assert self._source is not None
        for block_ofs in range(start, end, READ_BLOCK_BYTES):
            n = min(READ_BLOCK_BYTES, end - block_ofs)
            try:
                block = self._source.read(log_id, block_ofs, n)
            except OSError as exc:
                self._errors.append(f"Log {log_id} unreadable at {block_ofs}: {exc.strerror or exc}")
                return
            for i in range(0, len(block), LOG_DATA_LEN):
                chunk = block[i:i + LOG_DATA_LEN]
                yield self._mav.log_data_encode(log_id, block_ofs + i, len(chunk),
                                                list(chunk.ljust(LOG_DATA_LEN, b"\0")))
            if len(block) < n:  # the file is shorter than listed (replaced since): what there was
                self._errors.append(f"Log {log_id} ended at {block_ofs + len(block)} of {end} bytes")
                return


__all__ = ["LOG_DATA_LEN", "LogEntry", "LogSource", "LogTransfer", "reply_cost"]
