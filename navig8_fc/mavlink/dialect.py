"""The Navig8 MAVLink dialect as a Python module, generated from navig8.xml with pymavlink's mavgen.

    from navig8_fc.mavlink import dialect
    d = dialect.load()                      # the generated module (MAVLink 2, common + navig8)
    mav = dialect.new_mav(sysid=1, compid=dialect.COMPID_BRIDGE)
    frame = d.MAVLink_navig8_sim_status_message(1, 0, d.NAVIG8_SIM_STATE_RUNNING, 0.0, 0.0, 0).pack(mav)

Only the XML is committed. The module is generated on first use and cached as
`<cache>/navig8_<key>.py`, where the key hashes navig8.xml, the included XMLs and the pymavlink version
(pymavlink ships common.xml, so a pymavlink upgrade regenerates). The cache directory is
`$NAVIG8_CACHE_DIR`, else `~/.cache/navig8`, else a per-user temporary directory when neither is
usable. A directory is used only when it is the user's own (not a symlink, owned by the current user) and private:
mode 0700, tightened when the user's own directory is looser. A directory someone else owns (a `/tmp/navig8-<uid>`
planted before the first run) is never used: the cache holds code the process executes (the generated module and
its marshalled code), so a foreign or shared directory would run whatever was planted there. When no candidate
qualifies, a fresh private temporary directory is used for this process. Generation writes into a private
temporary directory and publishes with os.replace, so concurrent processes (the bridge and the FC start together)
never see a half-written module; the worst case is that both generate the same file once.

mavgen resolves `<include>` relative to the dialect file, so development.xml, common.xml, standard.xml and minimal.xml
are copied from pymavlink's package (pymavlink/dialects/v20/) beside navig8.xml in the build
directory.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import marshal
import os
import shutil
import stat
import sys
import tempfile
import threading
import time
from pathlib import Path
from types import ModuleType
from typing import Any

DIALECT_XML = Path(__file__).with_name("navig8.xml")
INCLUDED_XMLS = ("development.xml", "common.xml", "standard.xml", "minimal.xml")

# Extension fields of upstream common.xml that pymavlink's bundled copy (ArduPilot's, 2.4.50 = the newest on PyPI)
# lacks, added to the build's copy of common.xml before mavgen runs (the mission protocol's plan identities;
# docs/gcs.md "opaque_id"). Extension fields do not enter CRC_EXTRA, so these messages stay wire-compatible with
# every other dialect: a peer without the fields drops the trailing bytes, a peer with them reads them. A
# pymavlink that already has a field is left as it is.
COMMON_EXTENSIONS: dict[str, tuple[tuple[str, str], ...]] = {
    "MISSION_COUNT": (("opaque_id", "Id of current on-vehicle mission, fence, or rally point plan (on-vehicle "
                                    "plan identity). 0: unknown."),),
    "MISSION_ACK": (("opaque_id", "Id of new on-vehicle mission, fence, or rally point plan (on upload to vehicle). "
                                  "0: unknown."),),
    "MISSION_CURRENT": (("mission_id", "Id of current on-vehicle mission plan, or 0 if IDs are not supported or "
                                       "there is no mission loaded."),
                        ("fence_id", "Id of current on-vehicle fence plan, or 0 if IDs are not supported or there "
                                     "is no fence loaded."),
                        ("rally_points_id", "Id of current on-vehicle rally point plan, or 0 if IDs are not "
                                            "supported or there are no rally points loaded.")),
}


def patch_common(xml: str) -> str:
    """common.xml with COMMON_EXTENSIONS appended to its messages' extension fields (uint32_t each)."""
    for message, fields in COMMON_EXTENSIONS.items():
        start = xml.index(f'name="{message}">')
        end = xml.index("</message>", start)
        if "<extensions/>" not in xml[start:end]:
            raise RuntimeError(f"common.xml's {message} has no extension fields; COMMON_EXTENSIONS must be revisited")
        new = "".join(f'<field type="uint32_t" name="{name}">{text}</field>\n      ' for name, text in fields
                      if f'name="{name}"' not in xml[start:end])
        xml = xml[:end] + new + xml[end:]
    return xml


# Component ids on the bridge link: the FC is the autopilot, the bridge a user component.
COMPID_FC = 1  # MAV_COMP_ID_AUTOPILOT1
COMPID_BRIDGE = 25  # MAV_COMP_ID_USER1

# MAV_CMD_USER_1 of common.xml. The XML cannot declare a second name for the value (mavgen rejects
# duplicate enum values and common.xml names every vendor slot 31000-31014), so load() adds this alias.
MAV_CMD_NAVIG8_ARM_JOINTS = 31010

_lock = threading.Lock()
_module: ModuleType | None = None
last_generation_s: float | None = None  # wall time of the last generation in this process (None: cache hit)


def _pymavlink_dir() -> Path:
    import pymavlink

    return Path(pymavlink.__file__).resolve().parent


def included_xml_dir() -> Path:
    """Where pymavlink keeps common.xml and its includes (MAVLink 2 dialects)."""
    d = _pymavlink_dir() / "dialects" / "v20"
    missing = [n for n in INCLUDED_XMLS if not (d / n).is_file()]
    if missing:
        raise FileNotFoundError(f"pymavlink at {d} does not ship {missing}; cannot generate the navig8 dialect")
    return d


def cache_key() -> str:
    """Hash of everything the generated module depends on."""
    from pymavlink import __version__ as pymavlink_version

    h = hashlib.sha256()
    h.update(f"pymavlink={pymavlink_version};python3;wire=2.0\n".encode())
    h.update(repr(COMMON_EXTENSIONS).encode())
    h.update(DIALECT_XML.read_bytes())
    inc = included_xml_dir()
    for name in INCLUDED_XMLS:
        h.update(name.encode())
        h.update((inc / name).read_bytes())
    return h.hexdigest()[:16]


def _private_dir(p: Path) -> bool:
    """p exists (created 0700 if missing), is a real directory the current user owns with mode 0700, and is writable."""
    try:
        p.mkdir(mode=0o700, parents=True, exist_ok=True)
        st = os.lstat(p)
        if not stat.S_ISDIR(st.st_mode):  # a symlink (or a file): never followed
            return False
        if hasattr(os, "getuid"):
            if st.st_uid != os.getuid():
                return False
            if st.st_mode & 0o077:
                os.chmod(p, 0o700)  # ours but readable or writable by others: tighten it
                if os.lstat(p).st_mode & 0o077:
                    return False
        with tempfile.NamedTemporaryFile(dir=p, prefix=".probe-"):
            pass
        return True
    except OSError:
        return False


def cache_dir() -> Path:
    """The first private, writable one of $NAVIG8_CACHE_DIR, ~/.cache/navig8, <tmp>/navig8-<uid> (module docstring);
    else a fresh private temporary directory."""
    candidates = []
    env = os.environ.get("NAVIG8_CACHE_DIR")
    if env:
        candidates.append(Path(env).expanduser())
    candidates.append(Path.home() / ".cache" / "navig8")
    uid = os.getuid() if hasattr(os, "getuid") else 0
    candidates.append(Path(tempfile.gettempdir()) / f"navig8-{uid}")
    for c in candidates:
        if _private_dir(c):
            return c
    return Path(tempfile.mkdtemp(prefix="navig8-"))  # 0700, ours, new


def generate(out_py: Path) -> None:
    """Run mavgen on navig8.xml (with its includes copied beside it) and publish out_py atomically."""
    from pymavlink.generator import mavgen

    out_py = Path(out_py)
    out_py.parent.mkdir(parents=True, exist_ok=True)
    inc = included_xml_dir()
    with tempfile.TemporaryDirectory(dir=out_py.parent, prefix=".gen-") as tmp:
        build = Path(tmp)
        shutil.copyfile(DIALECT_XML, build / "navig8.xml")
        for name in INCLUDED_XMLS:
            shutil.copyfile(inc / name, build / name)
        common = build / "common.xml"
        common.write_text(patch_common(common.read_text(encoding="utf-8")), encoding="utf-8")
        tmp_py = build / "navig8.py"
        opts = mavgen.Opts(str(tmp_py), wire_protocol="2.0", language="Python3", validate=True, strict_units=False)
        chatter = io.StringIO()  # mavgen prints its progress; keep it for the error message only
        try:
            with contextlib.redirect_stdout(chatter):
                ok = mavgen.mavgen(opts, [str(build / "navig8.xml")])
        except SystemExit as e:  # mavgen calls exit() on some XML errors
            raise RuntimeError(f"mavgen failed on navig8.xml:\n{chatter.getvalue()}") from e
        if not ok or not tmp_py.is_file():
            raise RuntimeError(f"mavgen failed on navig8.xml:\n{chatter.getvalue()}")
        os.replace(tmp_py, out_py)


def _code_for(path: Path) -> Any:
    """Compiled code of the generated module, cached beside it as marshal data.

    Compiling the 1.8 MB module costs ~0.3 s, loading the marshalled code ~5 ms. The normal __pycache__
    is not used because PYTHONDONTWRITEBYTECODE (set in CI and some shells) would disable it.
    """
    code_path = path.with_name(f"{path.stem}.{sys.implementation.cache_tag}.code")
    if code_path.is_file():
        try:
            return marshal.loads(code_path.read_bytes())
        except (ValueError, EOFError, TypeError):
            pass  # corrupt or foreign: recompile below
    code = compile(path.read_bytes(), str(path), "exec")
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".code-")
        with os.fdopen(fd, "wb") as f:
            f.write(marshal.dumps(code))
        os.replace(tmp, code_path)
    except OSError:
        pass  # a read-only cache still works, only slower
    return code


def _import_from(path: Path, name: str) -> ModuleType:
    code = _code_for(path)
    mod = ModuleType(name)
    mod.__file__ = str(path)
    sys.modules[name] = mod  # registered before exec so lookups by module name (pickle, typing) work
    try:
        exec(code, mod.__dict__)
    except BaseException:
        sys.modules.pop(name, None)
        raise
    return mod


def _add_aliases(mod: ModuleType) -> None:
    if mod.MAV_CMD_USER_1 != MAV_CMD_NAVIG8_ARM_JOINTS:
        raise RuntimeError("common.xml moved MAV_CMD_USER_1; the arm joint command id must be revisited")
    mod.MAV_CMD_NAVIG8_ARM_JOINTS = MAV_CMD_NAVIG8_ARM_JOINTS
    # Tools that print enum descriptions (MAVProxy, mavlink inspectors in Python) show our meaning.
    entry = mod.enums["MAV_CMD"][MAV_CMD_NAVIG8_ARM_JOINTS]
    entry.description = (
        "Navig8: arm joint targets (alias MAV_CMD_NAVIG8_ARM_JOINTS). param1-3: q1, q2, q3 targets in degrees; "
        "param4: 0 = ignore, 1 = apply."
    )
    entry.param.update({1: "q1 target (deg)", 2: "q2 target (deg)", 3: "q3 target (deg)", 4: "apply (0/1)"})


def load() -> Any:
    """The generated dialect module (generated on first use, then cached on disk and in the process)."""
    global _module, last_generation_s
    if _module is not None:
        return _module
    with _lock:
        if _module is not None:
            return _module
        key = cache_key()
        path = cache_dir() / f"navig8_{key}.py"
        if not path.is_file():
            t0 = time.perf_counter()
            generate(path)
            last_generation_s = time.perf_counter() - t0
        name = f"navig8_fc_mavlink_generated_{key}"
        try:
            mod = _import_from(path, name)
        except (SyntaxError, ImportError, AttributeError, NameError):
            # a corrupt cache entry (disk full, manual edit): regenerate once
            path.with_name(f"{path.stem}.{sys.implementation.cache_tag}.code").unlink(missing_ok=True)
            generate(path)
            mod = _import_from(path, name)
        _add_aliases(mod)
        _module = mod
        return mod


def new_mav(sysid: int, compid: int) -> Any:
    """A MAVLink 2 encoder/parser (no file) for this dialect; malformed input yields BAD_DATA, never raises."""
    d = load()
    mav = d.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.robust_parsing = True
    return mav


__all__ = [
    "COMPID_BRIDGE",
    "COMPID_FC",
    "DIALECT_XML",
    "MAV_CMD_NAVIG8_ARM_JOINTS",
    "cache_dir",
    "cache_key",
    "generate",
    "load",
    "new_mav",
]
