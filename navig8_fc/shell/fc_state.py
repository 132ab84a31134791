"""The FC's state directory (--state-dir, one set of files per --instance): the parameter file, the uploaded mission
plan and the signing key, opened at start and restored into the GCS service before the first step (each says in
the log what it found). Without --state-dir nothing is stored."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from navig8_fc.links.signing import LinkSigning
from navig8_fc.mission.store import MissionStore
from navig8_fc.params.store import ParamStore, default_state_path
from navig8_fc.shell.gcs_service import GcsService
from navig8_fc.shell.signing_keys import KeyFile


@dataclass(frozen=True)
class FcState:
    """The stores of one FC instance (module docstring); all None without --state-dir."""

    params: ParamStore | None
    missions: MissionStore | None
    signing_key: KeyFile | None

    @staticmethod
    def open(state_dir: str | Path | None, instance: int) -> FcState:
        if not state_dir:
            return FcState(None, None, None)
        return FcState(ParamStore(default_state_path(state_dir, instance)),
                       MissionStore(default_state_path(state_dir, instance, "fc_mission")),
                       KeyFile(default_state_path(state_dir, instance, "fc_signing")))  # docs/security.md

    def restore(self, gcs: GcsService, signing: LinkSigning, defaults: bool, log_event: Callable[[str], None]) -> None:
        """The signing key, the mission plan and (unless `defaults`, --defaults) the parameters, as stored."""
        for line in signing.load():
            log_event(line)
        if self.missions is not None:
            reason = gcs.mission.load_stored()
            n = len(gcs.mission.plan().items)
            log_event(f"mission plan loaded from {self.missions.path} ({n} items)" if n else "no stored mission plan")
            if reason:
                log_event(reason)
        if self.params is not None and not defaults:
            loaded = gcs.load_stored_params()
            if loaded.ok:
                log_event(f"parameters loaded from {self.params.path} ({loaded.applied} values)")
            for line in loaded.report():  # also STATUSTEXT at the first ground-station contact
                log_event(line)
        elif defaults:
            log_event("starting from default parameters (--defaults)")
