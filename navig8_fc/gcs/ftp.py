"""A read-only MAVFTP server (FILE_TRANSFER_PROTOCOL, https://mavlink.io/en/services/ftp.html) over a fixed set of
in-memory files: the component metadata QGroundControl downloads (navig8_fc.gcs.metadata). docs/gcs.md.

Served (each request gets its reply at once, seq = request seq + 1; a burst's packets count on from there):
- OpenFileRO: a path in the file set (an optional leading "/" and the "mftp://[;comp=N]" prefix accepted) ->
  ACK with a new session and the file size (uint32); any ".." path segment -> NAK FileProtected (no traversal, ever);
  an unknown path -> NAK FileNotFound; all sessions in use -> NAK NoSessionsAvailable;
- ReadFile: size bytes at offset -> ACK with the data (at most 239), NAK EOF at or past the end;
- BurstReadFile: up to BURST_MAX_PACKETS ACKs of up to 239 bytes from offset (the last one burst_complete = 1; the
  client asks for the next burst from there), and NAK EOF once the file's end is sent (the download ends on that
  EOF; at or past the end: the NAK alone);
- ListDirectory: "/" lists the directory (D), a directory lists its files as "F<name>\\t<size>" entries from
  entry index = offset; past the last entry NAK EOF;
- CalcFileCRC32: ACK with the file's CRC32 (zlib's);
- TerminateSession: closes the session (unknown session: NAK InvalidSession); ResetSessions: closes the sender's.
Sessions belong to the requester that opened them (`owner`: system id, component id and where it sent from): another
requester's ReadFile, BurstReadFile or TerminateSession on them gets NAK InvalidSession, its ResetSessions leaves
them open. One owner holds at most MAX_SESSIONS_PER_OWNER sessions (NAK NoSessionsAvailable beyond); when every
session is taken, one idle for SESSION_IDLE_S is reclaimed for a new OpenFileRO.
Refused at once: every request that would write (CreateFile, OpenFileWO, WriteFile, CreateDirectory, RemoveFile,
RemoveDirectory, Rename, TruncateFile) -> NAK FileProtected (the files are read-only); any other opcode -> NAK
UnknownCommand. Our own replies (ACK/NAK) and runts are never answered.

Pure: payload bytes in, payload bytes out (the caller wraps them in FILE_TRANSFER_PROTOCOL messages). FtpService
paces the replies per source (navig8_fc.gcs.ftp_pacing): docs/security.md, "MAVFTP".
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Hashable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

from pymavlink.dialects.v20 import common as M

from navig8_fc.gcs.ftp_pacing import ReplyPacer
from navig8_fc.gcs.params import is_for_us

FTP_PAYLOAD_LEN = 251
HEADER = struct.Struct("<HBBBBBBI")  # seq, session, opcode, size, req_opcode, burst_complete, padding, offset
MAX_DATA = FTP_PAYLOAD_LEN - HEADER.size  # 239
MAX_SESSIONS = 4
MAX_SESSIONS_PER_OWNER = 2  # QGroundControl and MAVSDK use one session at a time
# A burst ends after this many packets (burst_complete = 1) and the client asks for the next from where it ended, as
# MAVSDK's client does ("This burst is complete but the file isn't", mavlink_ftp_client.cpp): one request draws at
# most ~2 KB, so a request repeated or left behind does not stream a whole file
BURST_MAX_PACKETS = 8
SESSION_IDLE_S = 2.0  # a session without a request for this long may be reclaimed when all are taken
URI_SCHEME = "mftp://"
_BY_IDS = "ids"  # a pacing key for a requester without a source (in-process callers): its ids

_WRITES = frozenset({
    M.MAV_FTP_OPCODE_CREATEFILE, M.MAV_FTP_OPCODE_OPENFILEWO, M.MAV_FTP_OPCODE_WRITEFILE,
    M.MAV_FTP_OPCODE_CREATEDIRECTORY, M.MAV_FTP_OPCODE_REMOVEFILE, M.MAV_FTP_OPCODE_REMOVEDIRECTORY,
    M.MAV_FTP_OPCODE_RENAME, M.MAV_FTP_OPCODE_TRUNCATEFILE,
})  # fmt: skip


def crc32(data: bytes) -> int:
    """CRC32 as MAVFTP's CalcFileCRC32 and COMPONENT_METADATA.file_crc use it (zlib's, the IEEE polynomial)."""
    return zlib.crc32(data) & 0xFFFFFFFF


class PathRefused(ValueError):
    """A path that tries to leave the served tree (a ".." segment)."""


def normalise_path(raw: str) -> str:
    """The served path a request names: "mftp://[;comp=N]" dropped, a leading "/" ensured, "." segments and
    doubled slashes removed. Raises PathRefused on any ".." segment (never resolved, so never escapes)."""
    p = raw.strip("\0").strip()
    if p.lower().startswith(URI_SCHEME):
        p = p[len(URI_SCHEME):]
        if p.startswith("[") and "]" in p:
            p = p[p.index("]") + 1:]
    parts = [s for s in p.replace("\\", "/").split("/") if s not in ("", ".")]
    if any(s == ".." for s in parts):
        raise PathRefused(raw)
    return "/" + "/".join(parts)


def _reply(seq: int, session: int, opcode: int, req_opcode: int, offset: int = 0, data: bytes = b"",
           burst_complete: int = 0) -> bytes:
    header = HEADER.pack(seq & 0xFFFF, session, opcode, len(data), req_opcode, burst_complete, 0, offset)
    return (header + data).ljust(FTP_PAYLOAD_LEN, b"\0")


@dataclass
class _Session:
    path: str
    owner: Hashable
    last_used_s: float


class Answer(NamedTuple):
    """A request's answer: the reply payloads to send at once and, for BurstReadFile, the burst's remaining
    payloads (lazy: the pacer draws them as the source's budget allows)."""

    replies: list[bytes]
    burst: Iterator[bytes] | None = None


class FtpServer:
    """Read-only MAVFTP over `files` (path -> content; paths absolute, e.g. "/navig8/parameters.json")."""

    def __init__(self, files: Mapping[str, bytes], max_sessions: int = MAX_SESSIONS,
                 max_sessions_per_owner: int = MAX_SESSIONS_PER_OWNER) -> None:
        self.files = dict(files)
        self.max_sessions = max_sessions
        self.max_sessions_per_owner = max_sessions_per_owner
        self._sessions: dict[int, _Session] = {}
        self.dirs = {p.rsplit("/", 1)[0] or "/" for p in self.files}

    @property
    def open_sessions(self) -> int:
        return len(self._sessions)

    def handle(self, request_payload: bytes | list[int], owner: Hashable = None, now_s: float = 0.0) -> list[bytes]:
        """The reply payloads (251 bytes each) to one request payload, a burst's all at once; [] for our own
        replies and runts."""
        answer = self.answer(request_payload, owner, now_s)
        return answer.replies + (list(answer.burst) if answer.burst is not None else [])

    def answer(self, request_payload: bytes | list[int], owner: Hashable = None, now_s: float = 0.0) -> Answer:
        """The answer to one request payload from `owner` (module docstring)."""
        raw = bytes(request_payload)
        if len(raw) < HEADER.size:
            return Answer([])
        seq, session, opcode, size, _req, _burst, _pad, offset = HEADER.unpack_from(raw)
        if opcode in (M.MAV_FTP_OPCODE_ACK, M.MAV_FTP_OPCODE_NAK):
            return Answer([])
        data = raw[HEADER.size:HEADER.size + min(size, MAX_DATA)]
        rseq = seq + 1

        def nak(err: int, sess: int = session) -> Answer:
            return Answer([_reply(rseq, sess, M.MAV_FTP_OPCODE_NAK, opcode, data=bytes([err]))])

        def ack(payload: bytes = b"", sess: int = session, off: int = 0) -> Answer:
            return Answer([_reply(rseq, sess, M.MAV_FTP_OPCODE_ACK, opcode, off, payload)])

        if opcode in _WRITES:
            return nak(M.MAV_FTP_ERR_FILEPROTECTED)
        if opcode == M.MAV_FTP_OPCODE_RESETSESSION:
            for sid in [i for i, s in self._sessions.items() if s.owner == owner]:
                del self._sessions[sid]
            return ack()
        mine = self._sessions.get(session)
        if mine is not None and mine.owner != owner:
            mine = None  # another requester's session: as if it did not exist
        if opcode == M.MAV_FTP_OPCODE_TERMINATESESSION:
            if mine is None:
                return nak(M.MAV_FTP_ERR_INVALIDSESSION)
            del self._sessions[session]
            return ack()
        if opcode in (M.MAV_FTP_OPCODE_OPENFILERO, M.MAV_FTP_OPCODE_CALCFILECRC, M.MAV_FTP_OPCODE_LISTDIRECTORY):
            try:
                path = normalise_path(data.decode("utf-8", errors="replace"))
            except PathRefused:
                return nak(M.MAV_FTP_ERR_FILEPROTECTED)
            if opcode == M.MAV_FTP_OPCODE_LISTDIRECTORY:
                return Answer(self._list(path, offset, rseq, session))
            content = self.files.get(path)
            if content is None:
                return nak(M.MAV_FTP_ERR_FILENOTFOUND)
            if opcode == M.MAV_FTP_OPCODE_CALCFILECRC:
                return ack(struct.pack("<I", crc32(content)))
            new = self._open(path, owner, now_s)
            if new is None:
                return nak(M.MAV_FTP_ERR_NOSESSIONSAVAILABLE)
            return ack(struct.pack("<I", len(content)), sess=new)
        if opcode in (M.MAV_FTP_OPCODE_READFILE, M.MAV_FTP_OPCODE_BURSTREADFILE):
            if mine is None:
                return nak(M.MAV_FTP_ERR_INVALIDSESSION)
            mine.last_used_s = now_s
            content = self.files[mine.path]
            if offset >= len(content):
                return Answer([_reply(rseq, session, M.MAV_FTP_OPCODE_NAK, opcode, offset,
                                      bytes([M.MAV_FTP_ERR_EOF]), 1)])
            if opcode == M.MAV_FTP_OPCODE_READFILE:
                n = min(size or MAX_DATA, MAX_DATA)
                return ack(content[offset:offset + n], off=offset)
            return Answer([], _burst_packets(content, offset, rseq, session))
        return nak(M.MAV_FTP_ERR_UNKNOWNCOMMAND)

    def _open(self, path: str, owner: Hashable, now_s: float) -> int | None:
        """A new session for `owner` (None: none left for it)."""
        if sum(s.owner == owner for s in self._sessions.values()) >= self.max_sessions_per_owner:
            return None
        if len(self._sessions) >= self.max_sessions:
            idle = [(s.last_used_s, i) for i, s in self._sessions.items() if now_s - s.last_used_s >= SESSION_IDLE_S]
            if not idle:
                return None
            del self._sessions[min(idle)[1]]
        new = next(i for i in range(256) if i not in self._sessions)
        self._sessions[new] = _Session(path, owner, now_s)
        return new

    def _list(self, path: str, offset: int, rseq: int, session: int) -> list[bytes]:
        if path == "/":
            entries = [f"D{d.lstrip('/')}" for d in sorted(self.dirs) if d != "/"]
        elif path in self.dirs:
            entries = [f"F{p.rsplit('/', 1)[1]}\t{len(c)}" for p, c in sorted(self.files.items())
                       if (p.rsplit("/", 1)[0] or "/") == path]
        else:
            return [_reply(rseq, session, M.MAV_FTP_OPCODE_NAK, M.MAV_FTP_OPCODE_LISTDIRECTORY,
                           data=bytes([M.MAV_FTP_ERR_FILENOTFOUND]))]
        if offset >= len(entries):
            return [_reply(rseq, session, M.MAV_FTP_OPCODE_NAK, M.MAV_FTP_OPCODE_LISTDIRECTORY, offset,
                           bytes([M.MAV_FTP_ERR_EOF]))]
        data = b""
        for e in entries[offset:]:  # as many whole entries as fit, each NUL-terminated
            b = e.encode() + b"\0"
            if len(data) + len(b) > MAX_DATA:
                break
            data += b
        return [_reply(rseq, session, M.MAV_FTP_OPCODE_ACK, M.MAV_FTP_OPCODE_LISTDIRECTORY, offset, data)]


def _burst_packets(content: bytes, offset: int, rseq: int, session: int) -> Iterator[bytes]:
    """BurstReadFile's replies from `offset`: up to BURST_MAX_PACKETS ACKs of up to MAX_DATA bytes, the last one
    burst_complete = 1; NAK EOF after the file's last byte."""
    stop = min(len(content), offset + BURST_MAX_PACKETS * MAX_DATA)
    k = 0
    for k, off in enumerate(range(offset, stop, MAX_DATA)):
        chunk = content[off:min(off + MAX_DATA, stop)]
        last = off + len(chunk) >= stop
        yield _reply(rseq + k, session, M.MAV_FTP_OPCODE_ACK, M.MAV_FTP_OPCODE_BURSTREADFILE, off, chunk, int(last))
    if stop == len(content):
        yield _reply(rseq + k + 1, session, M.MAV_FTP_OPCODE_NAK, M.MAV_FTP_OPCODE_BURSTREADFILE, len(content),
                     bytes([M.MAV_FTP_ERR_EOF]), 1)


class FtpService:
    """FILE_TRANSFER_PROTOCOL messages for one component: requests addressed to it (target_network 0) answered by
    an FtpServer, each reply addressed to the requester. With a `pacer` (the FC), replies are paced per source
    (navig8_fc.gcs.ftp_pacing): `handle` returns what the source's budget affords at once, `poll` the rest as the
    budget refills; without one (in-process callers), everything at once."""

    def __init__(self, mav: Any, server: FtpServer, sysid: int | None = None, compid: int | None = None,
                 pacer: ReplyPacer | None = None) -> None:
        self._mav = mav
        self.server = server
        self._sysid = int(mav.srcSystem if sysid is None else sysid)
        self._compid = int(mav.srcComponent if compid is None else compid)
        self.pacer = pacer

    def handle(self, msg: Any, source: Hashable = None, now_s: float = 0.0) -> list[Any]:
        """The replies to send now to the sender of `msg` (`source`: where it came from; it and the sender's ids
        own the sessions it opens)."""
        if msg.get_type() != "FILE_TRANSFER_PROTOCOL" or not is_for_us(msg, self._sysid, self._compid):
            return []
        if int(getattr(msg, "target_network", 0)) != 0:
            return []
        to = (msg.get_srcSystem(), msg.get_srcComponent())
        answer = self.server.answer(msg.payload, (*to, source), now_s)
        if self.pacer is None:
            payloads = answer.replies + (list(answer.burst) if answer.burst is not None else [])
            return [self._encode(to, p) for p in payloads]
        key = source if source is not None else (_BY_IDS, *to)  # the budget is per place the replies go
        session = bytes(msg.payload)[2] if answer.burst is not None else 0
        self.pacer.add(key, to, now_s, answer.replies, answer.burst, session)
        return [self._encode(dest, p) for _key, dest, p in self.pacer.take(now_s, only=key)]

    def poll(self, now_s: float) -> list[tuple[Hashable, Any]]:
        """(source, reply) pairs the budgets afford now (bursts continuing, replies that waited)."""
        if self.pacer is None or not self.pacer.pending:
            return []
        return [(None if key[0] == _BY_IDS else key, self._encode(to, p)) for key, to, p in self.pacer.take(now_s)]

    def _encode(self, to: tuple[int, int], payload: bytes) -> Any:
        return self._mav.file_transfer_protocol_encode(0, to[0], to[1], list(payload))


__all__ = ["FTP_PAYLOAD_LEN", "HEADER", "MAX_DATA", "Answer", "FtpServer", "FtpService", "PathRefused", "crc32",
           "normalise_path"]
