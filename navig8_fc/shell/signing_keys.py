"""The MAVLink signing key at rest: `<state-dir>/fc_signing_<N>.json` (docs/security.md).

The links (`navig8_fc.links.signing.LinkSigning`) sign and check frames with the key in memory; the FC's shell owns
its state directory, so the file that keeps the key and its last timestamp between runs lives here, written the
way the parameter and mission stores write theirs (`params.store.write_atomic`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from navig8_fc.links.signing import KEY_LEN
from navig8_fc.params.store import write_atomic


class KeyFile:
    """The signing key and its last timestamp, owner-only (0600), written atomically."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    def load(self) -> tuple[bytes | None, int, str | None]:
        """(key or None, timestamp, problem): no file -> (None, 0, None)."""
        try:
            st = self.path.stat()
            if not self.path.is_file() or st.st_size > 4096:
                return None, 0, f"signing key file {self.path} is not a small regular file: not used"
            doc = json.loads(self.path.read_text(encoding="ascii"))
            key = bytes.fromhex(doc["key"])
            ts = int(doc.get("timestamp", 0))
        except FileNotFoundError:
            return None, 0, None
        except (OSError, ValueError, KeyError, TypeError, UnicodeDecodeError):
            return None, 0, f"signing key file {self.path} is unreadable or corrupt: not used"
        if len(key) != KEY_LEN:
            return None, 0, f"signing key file {self.path} does not hold a {KEY_LEN}-byte key: not used"
        problem = None
        if st.st_mode & 0o077:
            os.chmod(self.path, 0o600)
            problem = f"signing key file {self.path} was readable by others: now owner-only"
        return key, ts, problem

    def save(self, key: bytes, timestamp: int) -> None:
        # params.store.write_atomic: mkstemp creates the temp file 0600, and the rename keeps that mode
        write_atomic(self.path, json.dumps({"key": key.hex(), "timestamp": int(timestamp)}).encode("ascii"))
        os.chmod(self.path, 0o600)

    def remove(self) -> None:
        try:
            self.path.unlink()
        except FileNotFoundError:
            pass
