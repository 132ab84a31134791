"""The MAVLink signing key at rest: `<state-dir>/fc_signing_<N>.json` (docs/security.md).

The links (`navig8_fc.links.signing.LinkSigning`) sign and check frames with the key in memory; the FC's shell owns
its state directory, so the file that keeps the key, its last timestamp and the signed streams' last timestamps
between runs lives here, written the way the parameter and mission stores write theirs (`params.store.write_atomic`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from navig8_fc.links.signing import KEY_LEN, STREAMS_KEPT, StoredKey, StreamId
from navig8_fc.params.store import write_atomic

MAX_FILE_BYTES = 1024 + 64 * STREAMS_KEPT  # the key, the timestamp and at most STREAMS_KEPT streams


class KeyFile:
    """The signing key, the last timestamp and the streams' last timestamps, owner-only (0600), written
    atomically."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    def load(self) -> StoredKey:
        """No file -> no key, nothing to report."""
        try:
            st = self.path.stat()
            if not self.path.is_file() or st.st_size > MAX_FILE_BYTES:
                return _unusable(f"signing key file {self.path} is not a small regular file: not used")
            doc = json.loads(self.path.read_text(encoding="ascii"))
            key = bytes.fromhex(doc["key"])
            ts = int(doc.get("timestamp", 0))
            streams = {(int(link), int(sysid), int(compid)): int(t)
                       for link, sysid, compid, t in doc.get("streams", [])}
        except FileNotFoundError:
            return StoredKey(None, 0, {}, None)
        except (OSError, ValueError, KeyError, TypeError, UnicodeDecodeError):
            return _unusable(f"signing key file {self.path} is unreadable or corrupt: not used")
        if len(key) != KEY_LEN:
            return _unusable(f"signing key file {self.path} does not hold a {KEY_LEN}-byte key: not used")
        problem = None
        if st.st_mode & 0o077:
            os.chmod(self.path, 0o600)
            problem = f"signing key file {self.path} was readable by others: now owner-only"
        return StoredKey(key, ts, streams, problem)

    def save(self, key: bytes, timestamp: int, streams: dict[StreamId, int] | None = None) -> None:
        # params.store.write_atomic: mkstemp creates the temp file 0600, and the rename keeps that mode
        rows = [[*stream, int(t)] for stream, t in (streams or {}).items()]
        write_atomic(self.path, json.dumps({"key": key.hex(), "timestamp": int(timestamp),
                                            "streams": rows}).encode("ascii"))
        os.chmod(self.path, 0o600)

    def remove(self) -> None:
        try:
            self.path.unlink()
        except FileNotFoundError:
            pass


def _unusable(problem: str) -> StoredKey:
    return StoredKey(None, 0, {}, problem)
