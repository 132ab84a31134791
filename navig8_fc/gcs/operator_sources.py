"""Which sources speak for the operator (docs/security.md, "Who may command" and "MAVLink 2 signing").

A system id is only a claim: anyone who can send a datagram can claim 255. Two things the operator did are not
claims: the addresses they configured (the links' peers, `--gcs-port`, `--api-port`, `--gcs-link`) and the
signing key they set up. So:

- the GCS-loss failsafe listens only to HEARTBEATs from a configured peer, or from anyone once signing is on
  (every frame that reaches the service then carries the key): one spoofed HEARTBEAT from a new address neither
  arms it nor, by going silent, lands the vehicle;
- SETUP_SIGNING is taken only while disarmed (PX4) and only from where `GCS_SIGN_LINK` says (ArduPilot takes it
  only over a secure channel such as USB): by default the ground-station link's configured peer.

A source is what the Outbox answers: the process gives (link name, address).
"""

from __future__ import annotations

from collections.abc import Callable, Container, Hashable, Iterable

GCS_LINK_NAME = "gcs"  # the link name (a source's first item) of the operator's ground-station link
# GCS_SIGN_LINK: where SETUP_SIGNING may come from (only while disarmed, whatever it says)
SIGN_SETUP_GCS_PEER = 0  # the GCS link's configured peer: the operator's own station (default)
SIGN_SETUP_PEERS = 1  # the configured peer of either link (GCS or API)
SIGN_SETUP_ANY = 2  # any allowed ground station (a bench with nobody else on the network)


class OperatorSources:
    """The configured peers, and whether a source speaks for the operator (module docstring)."""

    def __init__(self, configured: Container[Hashable] | Iterable[Hashable], signing_on: Callable[[], bool],
                 armed: Callable[[], bool]) -> None:
        """configured: the links' configured peers as sources (a container is asked as it is: the shell's knows the
        live connections of a TCP server link too); signing_on: whether a signing key is in force; armed: whether
        the vehicle is armed."""
        self._configured = configured if isinstance(configured, Container) else frozenset(configured)
        self._signing_on = signing_on
        self._armed = armed

    def configured(self, source: Hashable | None) -> bool:
        """One of the links' configured peers (None: an in-process caller, trusted)."""
        return source is None or source in self._configured

    def is_operator(self, source: Hashable | None) -> bool:
        """Whether a HEARTBEAT from `source` feeds the GCS-loss failsafe: a configured peer, or anyone while
        signing is on."""
        return self.configured(source) or self._signing_on()

    def signing_setup_refusal(self, source: Hashable | None, allowed_from: int) -> str | None:
        """Why SETUP_SIGNING from `source` is refused now (None: it may set the key); `allowed_from` is
        GCS_SIGN_LINK (SIGN_SETUP_*). Short: "SETUP_SIGNING refused: " and the reason fit one STATUSTEXT."""
        if self._armed():
            return "not while armed"
        if source is None or allowed_from >= SIGN_SETUP_ANY:
            return None
        if source in self._configured and (allowed_from == SIGN_SETUP_PEERS or _link_of(source) == GCS_LINK_NAME):
            return None
        return "configured GCS link only" if allowed_from == SIGN_SETUP_GCS_PEER else "configured links only"


def _link_of(source: Hashable) -> object:
    return source[0] if isinstance(source, tuple) and source else None
