"""Component metadata for QGroundControl (docs/gcs.md "Parameter metadata"): the general metadata file and the
parameter metadata JSON, generated from the parameter definitions (params/fc_params.yaml), served read-only over
MAVFTP (navig8_fc.gcs.ftp) and announced by COMPONENT_METADATA (397) / COMPONENT_INFORMATION (395).

What QGroundControl reads (src/Vehicle/ComponentInformation: RequestMetaDataTypeStateMachine, CompInfoGeneral,
CompInfoParam; src/FactSystem/FactMetaData createFromJsonObject):
- general file: {"version": 1, "metadataTypes": [{"type": COMP_METADATA_TYPE_PARAMETER (1), "uri": "mftp://...",
  "fileCrc": CRC32}]}; a type without "uri" or "fileCrc" is ignored;
- parameter file: {"version": 1, "parameters": [{"name", "type" (required), "shortDesc", "longDesc", "units",
  "default", "min", "max", "decimalPlaces", "group", "category", "rebootRequired", "volatile"}]}; type is
  QGC's value type name (Float for REAL32, Int32 for INT32).

Pure: definitions in, bytes out. CRC32 is zlib's (the IEEE polynomial, as PX4's crc32 and MAVFTP's CalcFileCRC32).
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from navig8_fc.gcs.ftp import crc32
from navig8_fc.params.registry import ParamDef

COMP_METADATA_TYPE_GENERAL = 0
COMP_METADATA_TYPE_PARAMETER = 1
METADATA_DIR = "/navig8"
GENERAL_PATH = f"{METADATA_DIR}/component_general.json"
PARAMETER_PATH = f"{METADATA_DIR}/parameters.json"
FTP_URI_PREFIX = "mftp://[;comp=1]"  # QGC strips "mftp://" and the optional [;comp=N] and opens the rest
_QGC_TYPES = {"REAL32": "Float", "INT32": "Int32"}
MAX_DECIMALS = 6
REBOOT_REQUIRED: frozenset[str] = frozenset()  # every parameter applies live (the FC rebuilds what depends on it)


def decimal_places(d: ParamDef) -> int:
    """Decimals QGC shows: 0 for integers; else the fewest that write default, min and max exactly (at most 6,
    at least 1)."""
    if d.type != "REAL32":
        return 0
    places = 1
    for v in (d.default, d.min, d.max):
        text = f"{float(v):.{MAX_DECIMALS}f}".rstrip("0")
        places = max(places, len(text.partition(".")[2]))
    return min(places, MAX_DECIMALS)


def parameter_entry(d: ParamDef) -> dict[str, Any]:
    """One parameter as QGC's FactMetaData JSON."""
    integer = d.type != "REAL32"
    num = (lambda v: int(v)) if integer else (lambda v: float(v))
    short, _, rest = d.description.partition(". ")
    entry: dict[str, Any] = {
        "name": d.name, "type": _QGC_TYPES[d.type], "shortDesc": short.rstrip(".") + ".",
        "longDesc": d.description, "default": num(d.default), "min": num(d.min), "max": num(d.max),
        "decimalPlaces": decimal_places(d), "group": d.name.partition("_")[0], "category": "Navig8",
        "rebootRequired": d.name in REBOOT_REQUIRED, "volatile": False,
    }
    if d.units:
        entry["units"] = d.units
    return entry


@dataclass(frozen=True)
class MetadataFiles:
    """The files served over MAVFTP (path -> bytes) and the general file's URI and CRC for COMPONENT_METADATA."""

    files: dict[str, bytes]

    @property
    def general_uri(self) -> str:
        return FTP_URI_PREFIX + GENERAL_PATH

    @property
    def general_crc(self) -> int:
        return crc32(self.files[GENERAL_PATH])


def build_metadata(definitions: Iterable[ParamDef]) -> MetadataFiles:
    """The parameter metadata JSON and the general file pointing at it (with its CRC)."""
    params = json.dumps({"version": 1, "parameters": [parameter_entry(d) for d in definitions]},
                        indent=1).encode()
    general = json.dumps({
        "version": 1,
        "vendorName": "Navig8", "modelName": "Navig8-UAM SITL", "firmwareVersion": "0.1.0",
        "metadataTypes": [{"type": COMP_METADATA_TYPE_PARAMETER, "uri": FTP_URI_PREFIX + PARAMETER_PATH,
                           "fileCrc": crc32(params)}],
    }, indent=1).encode()
    return MetadataFiles({GENERAL_PATH: general, PARAMETER_PATH: params})


MSG_ID_COMPONENT_INFORMATION = 395
MSG_ID_COMPONENT_METADATA = 397


def component_metadata_message(mav: Any, msg_id: int, files: MetadataFiles, boot_ms: int) -> list[Any] | None:
    """COMPONENT_METADATA (397) or the deprecated COMPONENT_INFORMATION (395) answering MAV_CMD_REQUEST_MESSAGE
    (QGC asks for 397 first, then 395 if refused); None for any other message id. mav: the navig8 dialect's
    MAVLink object (pymavlink's common.xml lacks both messages; navig8.xml declares them as upstream does)."""
    if msg_id == MSG_ID_COMPONENT_METADATA:
        return [mav.component_metadata_encode(boot_ms, files.general_crc, files.general_uri.encode())]
    if msg_id == MSG_ID_COMPONENT_INFORMATION:
        return [mav.component_information_encode(boot_ms, files.general_crc, files.general_uri.encode(), 0, b"")]
    return None


__all__ = [
    "COMP_METADATA_TYPE_PARAMETER", "FTP_URI_PREFIX", "GENERAL_PATH", "MSG_ID_COMPONENT_INFORMATION",
    "MSG_ID_COMPONENT_METADATA", "MetadataFiles", "PARAMETER_PATH", "build_metadata", "component_metadata_message",
    "decimal_places", "parameter_entry",
]
