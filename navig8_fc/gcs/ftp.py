"""A read-only MAVFTP server (FILE_TRANSFER_PROTOCOL, https://mavlink.io/en/services/ftp.html) over a fixed set of
in-memory files: the component metadata QGroundControl downloads (navig8_fc.gcs.metadata). docs/gcs.md.

Served (each request gets its reply at once, seq = request seq + 1; a burst's packets count on from there):
- OpenFileRO: a path in the file set (an optional leading "/" and the "mftp://[;comp=N]" prefix accepted) ->
  ACK with a new session and the file size (uint32); any ".." path segment -> NAK FileProtected (no traversal, ever);
  an unknown path -> NAK FileNotFound; all sessions in use -> NAK NoSessionsAvailable;
- ReadFile: size bytes at offset -> ACK with the data (at most 239), NAK EOF at or past the end;
- BurstReadFile: ACKs of up to 239 bytes from offset to the end of the file (the last one burst_complete = 1),
  then NAK EOF (QGroundControl's download ends on that EOF; at or past the end: the NAK alone);
- ListDirectory: "/" lists the directory (D), a directory lists its files as "F<name>\\t<size>" entries from
  entry index = offset; past the last entry NAK EOF;
- CalcFileCRC32: ACK with the file's CRC32 (zlib's);
- TerminateSession: closes the session (unknown session: NAK InvalidSession); ResetSessions: closes all.
Refused at once: every request that would write (CreateFile, OpenFileWO, WriteFile, CreateDirectory, RemoveFile,
RemoveDirectory, Rename, TruncateFile) -> NAK FileProtected (the files are read-only); any other opcode -> NAK
UnknownCommand. Our own replies (ACK/NAK) and runts are never answered.

Pure: payload bytes in, payload bytes out (the caller wraps them in FILE_TRANSFER_PROTOCOL messages).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Mapping
from typing import Any

from pymavlink.dialects.v20 import common as M

from navig8_fc.gcs.params import is_for_us

FTP_PAYLOAD_LEN = 251
HEADER = struct.Struct("<HBBBBBBI")  # seq, session, opcode, size, req_opcode, burst_complete, padding, offset
MAX_DATA = FTP_PAYLOAD_LEN - HEADER.size  # 239
MAX_SESSIONS = 4
URI_SCHEME = "mftp://"

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


class FtpServer:
    """Read-only MAVFTP over `files` (path -> content; paths absolute, e.g. "/navig8/parameters.json")."""

    def __init__(self, files: Mapping[str, bytes], max_sessions: int = MAX_SESSIONS) -> None:
        self.files = dict(files)
        self.max_sessions = max_sessions
        self._sessions: dict[int, str] = {}  # session id -> path
        self.dirs = {p.rsplit("/", 1)[0] or "/" for p in self.files}

    @property
    def open_sessions(self) -> int:
        return len(self._sessions)

    def handle(self, request_payload: bytes | list[int]) -> list[bytes]:
        """The reply payloads (251 bytes each) to one request payload; [] for our own replies and runts."""
        raw = bytes(request_payload)
        if len(raw) < HEADER.size:
            return []
        seq, session, opcode, size, _req, _burst, _pad, offset = HEADER.unpack_from(raw)
        if opcode in (M.MAV_FTP_OPCODE_ACK, M.MAV_FTP_OPCODE_NAK):
            return []
        data = raw[HEADER.size:HEADER.size + min(size, MAX_DATA)]
        rseq = seq + 1

        def nak(err: int, sess: int = session) -> list[bytes]:
            return [_reply(rseq, sess, M.MAV_FTP_OPCODE_NAK, opcode, data=bytes([err]))]

        def ack(payload: bytes = b"", sess: int = session, off: int = 0) -> list[bytes]:
            return [_reply(rseq, sess, M.MAV_FTP_OPCODE_ACK, opcode, off, payload)]

        if opcode in _WRITES:
            return nak(M.MAV_FTP_ERR_FILEPROTECTED)
        if opcode == M.MAV_FTP_OPCODE_RESETSESSION:
            self._sessions.clear()
            return ack()
        if opcode == M.MAV_FTP_OPCODE_TERMINATESESSION:
            if self._sessions.pop(session, None) is None:
                return nak(M.MAV_FTP_ERR_INVALIDSESSION)
            return ack()
        if opcode in (M.MAV_FTP_OPCODE_OPENFILERO, M.MAV_FTP_OPCODE_CALCFILECRC, M.MAV_FTP_OPCODE_LISTDIRECTORY):
            try:
                path = normalise_path(data.decode("utf-8", errors="replace"))
            except PathRefused:
                return nak(M.MAV_FTP_ERR_FILEPROTECTED)
            if opcode == M.MAV_FTP_OPCODE_LISTDIRECTORY:
                return self._list(path, offset, rseq, session)
            content = self.files.get(path)
            if content is None:
                return nak(M.MAV_FTP_ERR_FILENOTFOUND)
            if opcode == M.MAV_FTP_OPCODE_CALCFILECRC:
                return ack(struct.pack("<I", crc32(content)))
            if len(self._sessions) >= self.max_sessions:
                return nak(M.MAV_FTP_ERR_NOSESSIONSAVAILABLE)
            new = next(i for i in range(256) if i not in self._sessions)
            self._sessions[new] = path
            return ack(struct.pack("<I", len(content)), sess=new)
        if opcode in (M.MAV_FTP_OPCODE_READFILE, M.MAV_FTP_OPCODE_BURSTREADFILE):
            path = self._sessions.get(session)
            if path is None:
                return nak(M.MAV_FTP_ERR_INVALIDSESSION)
            content = self.files[path]
            if offset >= len(content):
                return [_reply(rseq, session, M.MAV_FTP_OPCODE_NAK, opcode, offset, bytes([M.MAV_FTP_ERR_EOF]), 1)]
            if opcode == M.MAV_FTP_OPCODE_READFILE:
                n = min(size or MAX_DATA, MAX_DATA)
                return ack(content[offset:offset + n], off=offset)
            out = []
            for k, off in enumerate(range(offset, len(content), MAX_DATA)):
                chunk = content[off:off + MAX_DATA]
                last = off + len(chunk) >= len(content)
                out.append(_reply(rseq + k, session, M.MAV_FTP_OPCODE_ACK, opcode, off, chunk, int(last)))
            out.append(_reply(rseq + len(out), session, M.MAV_FTP_OPCODE_NAK, opcode, len(content),
                              bytes([M.MAV_FTP_ERR_EOF]), 1))
            return out
        return nak(M.MAV_FTP_ERR_UNKNOWNCOMMAND)

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


class FtpService:
    """FILE_TRANSFER_PROTOCOL messages for one component: requests addressed to it (target_network 0) answered by
    an FtpServer, each reply addressed to the requester."""

    def __init__(self, mav: Any, server: FtpServer, sysid: int | None = None, compid: int | None = None) -> None:
        self._mav = mav
        self.server = server
        self._sysid = int(mav.srcSystem if sysid is None else sysid)
        self._compid = int(mav.srcComponent if compid is None else compid)

    def handle(self, msg: Any) -> list[Any]:
        if msg.get_type() != "FILE_TRANSFER_PROTOCOL" or not is_for_us(msg, self._sysid, self._compid):
            return []
        if int(getattr(msg, "target_network", 0)) != 0:
            return []
        src_sys, src_comp = msg.get_srcSystem(), msg.get_srcComponent()
        return [self._mav.file_transfer_protocol_encode(0, src_sys, src_comp, list(p))
                for p in self.server.handle(msg.payload)]


__all__ = ["FTP_PAYLOAD_LEN", "HEADER", "MAX_DATA", "FtpServer", "FtpService", "PathRefused", "crc32", "normalise_path"]
