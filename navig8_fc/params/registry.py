"""Parameter registry: definitions from params/fc_params.yaml, typed access, validation.

Pure state machine: no sockets, no files written, no clocks. The MAVLink parameter protocol,
persistence and STATUSTEXT live in the shell; they call `validate`/`set` and report the
`SetResult`. Names and order are fixed at load: a parameter's index is its position in the
YAML file (MAVLink param_index).

Rules checked on every set (each refusal carries a human-readable reason):
- the name exists; the value is a finite number; INT32 values are integral;
- min <= value <= max from the definition;
- cross-parameter rules: INDI_K_MIN <= INDI_K_MAX; INDI_LAMBDA_MIN above the critical eigenvalue;
- the stability floor (DESIGN §5): a K bound (or an actuator/sampling/filter parameter) that would
  let an eigenvalue of G_hat G^-1 fall below the critical eigenvalue of H(s) (Eq. 9-13) anywhere in
  the workspace is refused, and so is one that leaves the guaranteed smallest eigenvalue less than
  INDI_LAM_MARGIN times lambda_crit (the stated margin, docs/stability.md "The flown configuration"), lambda_crit
  being the loop's over the sim link as the shell measured it (`set_link`: lockstep unless told otherwise);
- `not_armed: true` in the YAML: the parameter changes the loop itself (rate, filters, actuator model,
  estimator mode) and is refused while armed (`set(..., armed=True)`).

The stability floor costs ~0.1-0.3 s (a workspace sweep), too long for the control thread: results are
cached by the values they depend on (`floor_key`), and `floor_needed` tells a caller which candidate would
need a fresh sweep, so the shell can compute it on a worker (`compute_floor`, pure) and `store_floor` the
result before the set runs (navig8_fc.shell.gcs_service). Without that, `set` computes it inline.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from navig8_fc.yaml_text import safe_load

MAX_NAME_LEN = 16  # MAVLink param_id is char[16]
TYPES = ("REAL32", "INT32")

# Parameters the stability floor depends on: a change to any of them re-runs the check.
STABILITY_PARAMS = frozenset(
    {"INDI_K_MIN", "INDI_K_MAX", "INDI_LAMBDA_MIN", "INDI_LAM_MARGIN", "ACT_WN", "ACT_ZETA", "INDI_RATE_HZ",
     "INDI_LPF_TAU", "INDI_LAM_REF", "INDI_KFL_MIN"}
)
# What the floor itself depends on (INDI_LAMBDA_MIN and INDI_LAM_MARGIN are compared against it afterwards): the
# cache key.
FLOOR_INPUTS = ("INDI_K_MIN", "INDI_K_MAX", "ACT_WN", "ACT_ZETA", "INDI_RATE_HZ", "INDI_LPF_TAU", "INDI_LAM_REF",
                "INDI_KFL_MIN")
# The flown-gain parameters (INDI_LAM_REF, INDI_KFL_MIN) when a caller's values lack them: the paper's K_hat flown
FLOWN_GAIN_DEFAULTS = {"INDI_LAM_REF": 1.0, "INDI_KFL_MIN": 0.0}
# The sim link's timing, beside the parameters in the values a floor is computed for (not parameters: measured by the
# FC's shell, `ParamRegistry.set_link`): how many ticks later than in lockstep the answers fly, and whether the FC's
# actuator model is told which answer flew (docs/stability.md, "Over a real-time link"). Absent: lockstep.
LINK_DELAY_KEY, LINK_TOLD_KEY = "link_delay_ticks", "link_model_told"
# The automatic link floor (INDI_KFL_LINK; navig8_fc/params/link_floor.py) beside them: a floor on the flown K of the
# rotational axes the FC raised over a late link, flown as max(INDI_KFL_MIN, it) (absent or 0: none). Not a parameter:
# INDI_KFL_MIN keeps the value a ground station set.
LINK_KFL_KEY = "link_k_floor"
# What the loop over a delayed link depends on besides FLOOR_INPUTS (its U0: lockstep's Pade H(s) does not read it)
LINK_FLOOR_INPUTS = ("INDI_U0_SRC", "INDI_U0_TAU")
LINK_U0_DEFAULTS = {"INDI_U0_SRC": 0, "INDI_U0_TAU": 0.2}  # when a caller's values lack them: the paper's measured U0


@dataclass(frozen=True)
class LinkTiming:
    """The sim link as the loop flies it: answers flown `delay_ticks` ticks later than in lockstep (0: lockstep), the
    actuator model told which answer flew (the bridge's cmd_time_usec echo) or not."""

    delay_ticks: int = 0
    model_told: bool = True

    def __post_init__(self) -> None:
        if self.delay_ticks < 0 or int(self.delay_ticks) != self.delay_ticks:
            raise ValueError(f"delay_ticks must be an integer >= 0, got {self.delay_ticks}")


LOCKSTEP = LinkTiming()


def link_of(values: Mapping[str, Any]) -> LinkTiming:
    """The link timing carried in a floor's values (lockstep when absent)."""
    return LinkTiming(int(values.get(LINK_DELAY_KEY, 0)), bool(values.get(LINK_TOLD_KEY, True)))
FLOOR_CACHE_SIZE = 256


class ParamDefinitionError(ValueError):
    """The parameter definition file is malformed (raised at startup)."""


@dataclass(frozen=True)
class ParamDef:
    name: str
    type: str
    default: float
    min: float
    max: float
    units: str
    description: str
    index: int
    not_armed: bool = False  # refused while armed (changes the loop itself)

    def coerce(self, value: float) -> float | int:
        """The stored form: INT32 as int, REAL32 rounded to float32 (what MAVLink carries)."""
        if self.type == "INT32":
            return int(round(value))
        return float(np.float32(value))


@dataclass(frozen=True)
class SetResult:
    """Outcome of a set: the value now in force (the old one when refused) and why it was refused."""

    name: str
    accepted: bool
    value: float | int
    old_value: float | int
    reason: str | None = None


@dataclass(frozen=True)
class StabilityFloor:
    """Result of the stability-floor check for one candidate parameter set.

    H(s) is stable for eigenvalues in (lambda_crit, lambda_upper); lambda_upper is infinite for the usual
    actuator/filter settings, finite only for lightly damped actuators with long delays (docs/stability.md).
    """

    lambda_crit: float
    min_eigenvalue: float
    lambda_upper: float = math.inf
    max_eigenvalue: float = -math.inf  # only evaluated when lambda_upper is finite

    @property
    def ok(self) -> bool:
        return self.min_eigenvalue > self.lambda_crit and self.max_eigenvalue < self.lambda_upper

    @property
    def margin(self) -> float:
        """min_eigenvalue / lambda_crit: the factor by which the true control effectiveness may exceed the
        worst-case model before H(s) loses stability (inf when lambda_crit is 0, nan for a refusing floor)."""
        if not (math.isfinite(self.lambda_crit) and math.isfinite(self.min_eigenvalue)):
            return math.nan
        return math.inf if self.lambda_crit <= 0.0 else self.min_eigenvalue / self.lambda_crit


@dataclass(frozen=True)
class StabilityStatus:
    """The stability floor of the parameters in force, as telemetry (LAM_CRIT, LAM_MARGIN) and the log report it."""

    lambda_crit: float  # of H(s) for ACT_WN, ACT_ZETA, 1/INDI_RATE_HZ, INDI_LPF_TAU (Eq. 9-13)
    min_eigenvalue: float  # smallest Re eig(G_hat G^-1) guaranteed over the K box and the workspace
    margin: float  # min_eigenvalue / lambda_crit
    required_margin: float  # INDI_LAM_MARGIN
    lambda_min: float  # INDI_LAMBDA_MIN (the performance target, Sec. 3.2)
    link_delay_ticks: int = 0  # the sim link's delay the floor is computed for (LinkTiming; 0: lockstep)
    link_model_told: bool = True
    link_k_floor: float = 0.0  # the automatic link floor on the flown K in force (INDI_KFL_LINK; 0: none)

    @property
    def meets_margin(self) -> bool:
        return self.margin >= self.required_margin


StabilityCheck = Callable[[Mapping[str, float | int]], StabilityFloor]


class WorkspaceCache(Protocol):
    """Where the workspace Xi of a vehicle file may be kept between processes (the FC's: shell/xi_cache.py, on
    disk). It must pickle: the check travels to the floor worker with it."""

    def load(self, vehicle_path: str | None) -> np.ndarray | None: ...

    def store(self, vehicle_path: str | None, xi: np.ndarray) -> None: ...


class WorkspaceStabilityCheck:
    """λ_crit of H(s) for the actuator/sampling/filter parameters vs the smallest eigenvalue of K·Ξ
    over the arm workspace and object masses (navig8_fc.core.stability).

    Results are kept per process for the vehicle file and the floor inputs (the sweep is a pure function of
    them), so registries of one process (the FC's, a test's) compute each configuration once. `workspace_cache`
    keeps the workspace Xi between processes too: every FC start's floor worker then skips computing it (and
    loading numba for it)."""

    _memo: dict[tuple[Any, tuple[float, ...]], StabilityFloor] = {}
    _crit_memo: dict[tuple[Any, ...], float] = {}  # lambda_crit by what it depends on (_lambda_crit)
    # the workspace Xi (k_xi.workspace_xi: ~0.1 s, independent of every floor input) per vehicle file, so a new
    # configuration costs only its eigenvalues (~15 ms): a PARAM_SET is answered at once
    _workspace: dict[str | None, np.ndarray] = {}

    def __init__(self, vehicle_path: str | Path | None = None, workspace_cache: WorkspaceCache | None = None) -> None:
        self._vehicle_path = vehicle_path
        self._workspace_cache = workspace_cache

    def __call__(self, values: Mapping[str, float | int]) -> StabilityFloor:
        key = (None if self._vehicle_path is None else str(self._vehicle_path), floor_key(values))
        hit = self._memo.get(key)
        if hit is None:
            hit = self._compute(values)
            if len(self._memo) >= FLOOR_CACHE_SIZE:
                self._memo.pop(next(iter(self._memo)))
            self._memo[key] = hit
        return hit

    def _compute(self, values: Mapping[str, float | int]) -> StabilityFloor:
        from navig8_fc.core import k_xi, stability

        xi = self._workspace_xi()
        lam_crit = self._lambda_crit(values)
        k_min, k_max = flown_k_bounds(values)  # the K the INDI flies (INDI_LAM_REF, INDI_KFL_MIN), not K_hat's box
        min_eig = k_xi.min_eigenvalue_of_xi(xi, k_min, k_max)
        lam_up = stability.lambda_upper(
            float(values["ACT_WN"]), float(values["ACT_ZETA"]), 1.0 / float(values["INDI_RATE_HZ"]),
            float(values["INDI_LPF_TAU"]),
        )
        max_eig = -math.inf
        if math.isfinite(lam_up):  # rare (lightly damped, long delay): the slow side needs the full sweep
            from navig8_fc.core.vehicle import VehicleConfig

            max_eig = k_xi.k_bounds_analysis(VehicleConfig.load(self._vehicle_path), k_min, k_max).max_eigenvalue
        return StabilityFloor(lam_crit, min_eig, lam_up, max_eig)

    @classmethod
    def _lambda_crit(cls, values: Mapping[str, float | int]) -> float:
        """lambda_crit of the loop for `values` (the link's when they carry one), kept per process by what it depends
        on: the flown K's floor does not move it, so a search over that floor (link_floor.py) computes it once."""
        link = link_of(values)
        wn, zeta, rate, tl = (float(values[n]) for n in ("ACT_WN", "ACT_ZETA", "INDI_RATE_HZ", "INDI_LPF_TAU"))
        u0 = tuple(float(values.get(n, LINK_U0_DEFAULTS[n])) for n in LINK_FLOOR_INPUTS) if link.delay_ticks else ()
        key = (wn, zeta, rate, tl, link.delay_ticks, link.model_told, *u0)
        hit = cls._crit_memo.get(key)
        if hit is not None:
            return hit
        if link.delay_ticks == 0:  # lockstep: H(s) with the one-sample Pade delay, its conservative model
            from navig8_fc.core import stability

            lam_crit = stability.lambda_crit(wn, zeta, 1.0 / rate, tl)
        else:  # the answers fly later: the sampled loop with the commands in flight as states (exact, discrete)
            from navig8_fc.core.sampled_loop import link_lambda_crit

            lam_crit = link_lambda_crit(wn, zeta, rate, tl, "model" if int(u0[0]) == 1 else "measured", u0[1],
                                        link.delay_ticks, link.model_told)
        if len(cls._crit_memo) >= FLOOR_CACHE_SIZE:
            cls._crit_memo.pop(next(iter(cls._crit_memo)))
        cls._crit_memo[key] = lam_crit
        return lam_crit

    def _workspace_xi(self) -> np.ndarray:
        """The vehicle's workspace Xi: this process's, else the cache's, else computed (and given to the cache)."""
        path = None if self._vehicle_path is None else str(self._vehicle_path)
        xi = self._workspace.get(path)
        if xi is None and self._workspace_cache is not None:
            xi = self._workspace_cache.load(path)
        if xi is None:
            from navig8_fc.core import k_xi
            from navig8_fc.core.vehicle import VehicleConfig  # numba's kernels: only when Xi is computed here

            xi = k_xi.workspace_xi(VehicleConfig.load(self._vehicle_path))
            if self._workspace_cache is not None:
                self._workspace_cache.store(path, xi)
        self._workspace[path] = xi
        return xi


def _flag(raw: Mapping[str, Any], key: str) -> bool:
    v = raw.get(key, False)
    if not isinstance(v, bool):
        raise ValueError(f"{key} must be true or false, got {v!r}")
    return v


def run_floor(check: StabilityCheck, values: Mapping[str, float | int]) -> StabilityFloor:
    """`check(values)`; parameters the analysis itself refuses give a floor that refuses. Module-level, so a
    worker process can run it (the check and the values pickle)."""
    try:
        return check(values)
    except (ValueError, ArithmeticError):
        return StabilityFloor(math.inf, -math.inf)


def floor_key(values: Mapping[str, Any], link: LinkTiming | None = None,
              link_k_floor: float | None = None) -> tuple[float, ...]:
    """The values the stability floor depends on, as a cache key (the link's timing and, over a delayed link, U0; the
    automatic link floor when one is in force); `link`, `link_k_floor`: the timing and the link floor when `values` do
    not carry them (the registry's values in force)."""
    key = tuple(float(values[n] if n in values else FLOWN_GAIN_DEFAULTS[n]) for n in FLOOR_INPUTS)
    kfl = float(values.get(LINK_KFL_KEY, 0.0)) if link_k_floor is None else float(link_k_floor)
    if kfl > 0.0:
        key = (*key, -1.0, kfl)  # -1: a separator no delay takes, so the two tails never read alike
    link = link_of(values) if link is None else link
    if link.delay_ticks == 0:
        return key
    u0 = tuple(float(values.get(n, LINK_U0_DEFAULTS[n])) for n in LINK_FLOOR_INPUTS)
    return (*key, float(link.delay_ticks), float(link.model_told), *u0)


def flown_k_bounds(values: Mapping[str, float | int]) -> tuple[float, float]:
    """The box of the K the INDI flies (k_xi.flown_k_box): the Eq. 20 box [INDI_K_MIN, INDI_K_MAX] at the defaults
    (INDI_LAM_REF 1, INDI_KFL_MIN 0), else widened to hold lambda* K_hat and the flown floor (INDI_KFL_MIN, raised to
    the automatic link floor when `values` carry one: LINK_KFL_KEY)."""
    from navig8_fc.core import k_xi

    lam = float(values.get("INDI_LAM_REF", FLOWN_GAIN_DEFAULTS["INDI_LAM_REF"]))
    floor = max(float(values.get("INDI_KFL_MIN", FLOWN_GAIN_DEFAULTS["INDI_KFL_MIN"])),
                float(values.get(LINK_KFL_KEY, 0.0)))
    return k_xi.flown_k_box(float(values["INDI_K_MIN"]), float(values["INDI_K_MAX"]), lam, floor)


@functools.lru_cache(maxsize=8)  # ParamDefs are frozen and the tuple immutable: parsed once a process per text
def load_definitions(text: str) -> tuple[ParamDef, ...]:
    """Parse and check the YAML definitions (names, types, ranges, defaults)."""
    doc = safe_load(text)  # libyaml (yaml_text)
    if not isinstance(doc, dict) or not isinstance(doc.get("params"), list):
        raise ParamDefinitionError("parameter file must have a top-level 'params' list")
    defs: list[ParamDef] = []
    seen: set[str] = set()
    for i, raw in enumerate(doc["params"]):
        try:
            name = str(raw["name"])
            ptype = str(raw["type"])
            d = ParamDef(
                name=name,
                type=ptype,
                default=float(raw["default"]),
                min=float(raw["min"]),
                max=float(raw["max"]),
                units=str(raw.get("units", "")),
                description=str(raw["description"]).strip(),
                index=i,
                not_armed=_flag(raw, "not_armed"),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ParamDefinitionError(f"parameter #{i}: {exc!r}") from exc
        if not name or len(name) > MAX_NAME_LEN or not name.replace("_", "").isalnum() or name.upper() != name:
            raise ParamDefinitionError(f"{name!r}: names are UPPER_SNAKE, at most {MAX_NAME_LEN} chars")
        if "_" not in name:
            raise ParamDefinitionError(f"{name!r}: names carry a group prefix (GROUP_NAME)")
        if name in seen:
            raise ParamDefinitionError(f"{name!r} defined twice")
        if ptype not in TYPES:
            raise ParamDefinitionError(f"{name}: type {ptype!r} not in {TYPES}")
        if not (d.min <= d.default <= d.max):
            raise ParamDefinitionError(f"{name}: default {d.default} outside [{d.min}, {d.max}]")
        if ptype == "INT32" and any(v != int(v) for v in (d.default, d.min, d.max)):
            raise ParamDefinitionError(f"{name}: INT32 default/min/max must be integers")
        seen.add(name)
        defs.append(d)
    return tuple(defs)


class ParamRegistry:
    """The live parameter set of one flight controller."""

    def __init__(
        self,
        definitions: Iterable[ParamDef],
        stability_check: StabilityCheck | None = None,
        check_stability: bool = True,
    ) -> None:
        self._defs = tuple(definitions)
        self._by_name = {d.name: d for d in self._defs}
        self._values: dict[str, float | int] = {d.name: d.coerce(d.default) for d in self._defs}
        if stability_check is None and check_stability:
            stability_check = WorkspaceStabilityCheck()
        self._stability_check = stability_check
        self._generation = 0
        self._floors: dict[tuple[float, ...], StabilityFloor] = {}  # floor_key -> result (insertion = age)
        self._link = LOCKSTEP  # the sim link's timing the floor in force and the margin rule are computed for
        self._link_k_floor = 0.0  # the automatic link floor on the flown K (set_link_k_floor; 0: none)

    # --- construction -------------------------------------------------------------------------
    @staticmethod
    def definitions_text(path: str | Path | None = None) -> str:
        if path is None:
            return (files("navig8_params") / "fc_params.yaml").read_text()
        return Path(path).read_text()

    @classmethod
    def from_defaults(
        cls,
        path: str | Path | None = None,
        stability_check: StabilityCheck | None = None,
        check_stability: bool = True,
    ) -> ParamRegistry:
        return cls(load_definitions(cls.definitions_text(path)), stability_check, check_stability)

    # --- read access ----------------------------------------------------------------------------
    @property
    def definitions(self) -> tuple[ParamDef, ...]:
        return self._defs

    @property
    def generation(self) -> int:
        """Counts accepted changes, so consumers rebuild their typed config only when it moved."""
        return self._generation

    def __len__(self) -> int:
        return len(self._defs)

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def definition(self, name: str) -> ParamDef:
        try:
            return self._by_name[name]
        except KeyError:
            raise KeyError(f"unknown parameter {name!r}") from None

    def index_of(self, name: str) -> int:
        return self.definition(name).index

    def at_index(self, index: int) -> ParamDef:
        if not 0 <= index < len(self._defs):
            raise IndexError(f"parameter index {index} outside 0..{len(self._defs) - 1}")
        return self._defs[index]

    def get(self, name: str) -> float | int:
        if name not in self._values:
            raise KeyError(f"unknown parameter {name!r}")
        return self._values[name]

    __getitem__ = get

    def as_dict(self) -> dict[str, float | int]:
        return dict(self._values)

    def require(self, names: Iterable[str]) -> None:
        """Fail at startup when code asks for a parameter the definitions do not have."""
        missing = sorted(set(names) - set(self._by_name))
        if missing:
            raise ParamDefinitionError(f"code uses undefined parameters: {', '.join(missing)}")

    # --- validation -----------------------------------------------------------------------------
    def validate(self, name: str, value: float, armed: bool = False) -> str | None:
        """None when `value` may be set, otherwise the reason (for STATUSTEXT)."""
        candidate = self._candidate(name, value, armed)
        if isinstance(candidate, str):
            return candidate
        return self._cross_check(name, candidate)

    def _candidate(self, name: str, value: float, armed: bool) -> dict[str, float | int] | str:
        """Every value with `name` set to `value` when the per-parameter rules pass, else the refusal reason."""
        if name not in self._by_name:
            return f"unknown parameter {name!r}"
        d = self._by_name[name]
        try:
            v = float(value)
        except (TypeError, ValueError):
            return f"{name}: value {value!r} is not a number"
        if not math.isfinite(v):
            return f"{name}: value must be finite, got {v}"
        if d.type == "INT32" and v != int(v):
            return f"{name}: INT32 needs an integer, got {v}"
        cv = d.coerce(v)
        # Compare the float32 form against the float32 form of the limits: a GCS sends float32.
        lo, hi = d.coerce(d.min), d.coerce(d.max)
        if not (lo <= cv <= hi):
            return f"{name}: {v:g} outside [{d.min:g}, {d.max:g}] {d.units}".rstrip()
        if armed and d.not_armed and cv != self._values[name]:
            return f"{name}: cannot be changed while armed (it changes the control loop)"
        candidate = self.floor_values()
        candidate[name] = cv
        return candidate

    # --- the sim link's timing -------------------------------------------------------------------
    @property
    def link(self) -> LinkTiming:
        return self._link

    def set_link(self, link: LinkTiming) -> None:
        """The sim link's timing as the shell measured it: from now on the floor in force (LAM_CRIT, LAM_MARGIN)
        and the margin rule are those of the loop flown over it (not computed until a caller computes it:
        floor_in_force is None meanwhile, as after a reset)."""
        self._link = link

    @property
    def link_k_floor(self) -> float:
        """The automatic link floor on the flown K of the rotational axes in force (0: none; link_floor.py)."""
        return self._link_k_floor

    def set_link_k_floor(self, k_floor: float) -> None:
        """Fly the rotational axes' K at least `k_floor` (0: no link floor) beside INDI_KFL_MIN, whose value stays
        what a ground station set: the controller's configuration (`flown_values`), the floor in force and the
        margin rule take max(INDI_KFL_MIN, k_floor) from now on. A change counts as a parameter change (generation),
        so the flight stack applies it at its next step."""
        k = float(k_floor)
        if not (math.isfinite(k) and 0.0 <= k <= self._by_name["INDI_KFL_MIN"].max):
            raise ValueError(f"link K floor must be in [0, {self._by_name['INDI_KFL_MIN'].max:g}], got {k_floor!r}")
        if k != self._link_k_floor:
            self._link_k_floor = k
            self._generation += 1

    def flown_values(self) -> dict[str, float | int]:
        """The values the controller flies: the parameters in force, INDI_KFL_MIN raised to the automatic link floor
        when that is higher (as_dict: the parameters as a ground station sees them)."""
        values = dict(self._values)
        if self._link_k_floor > float(values["INDI_KFL_MIN"]):
            values["INDI_KFL_MIN"] = self._link_k_floor
        return values

    def floor_values(self) -> dict[str, Any]:
        """The values in force with the link's timing and the automatic link floor: what the floor in force is computed
        for (run_floor)."""
        values: dict[str, Any] = dict(self._values)
        if self._link.delay_ticks > 0:
            values[LINK_DELAY_KEY] = self._link.delay_ticks
            values[LINK_TOLD_KEY] = self._link.model_told
        if self._link_k_floor > 0.0:
            values[LINK_KFL_KEY] = self._link_k_floor
        return values

    def _needs_floor(self, name: str) -> bool:
        """A change to `name` is checked against the stability floor (over a delayed link U0's parameters too)."""
        return name in STABILITY_PARAMS or (self._link.delay_ticks > 0 and name in LINK_FLOOR_INPUTS)

    # --- stability floor (cached; computable off the caller's thread) ----------------------------
    def floor_needed(self, name: str, value: float, armed: bool = False) -> dict[str, float | int] | None:
        """The candidate values whose floor a set of `name` to `value` would compute now (not cached), else
        None (no floor needed, cached, or refused earlier by a cheap rule)."""
        if not self._needs_floor(name) or self._stability_check is None:
            return None
        candidate = self._candidate(name, value, armed)
        if isinstance(candidate, str) or floor_key(candidate) in self._floors:
            return None
        return candidate

    def compute_floor(self, values: Mapping[str, float | int]) -> StabilityFloor:
        """The floor for `values` (pure; see `run_floor`)."""
        assert self._stability_check is not None
        return run_floor(self._stability_check, values)

    @property
    def stability_check(self) -> StabilityCheck | None:
        """The check itself, for a caller that runs it elsewhere (`run_floor` in a worker process)."""
        return self._stability_check

    def store_floor(self, values: Mapping[str, float | int], floor: StabilityFloor) -> None:
        self._floors[floor_key(values)] = floor
        while len(self._floors) > FLOOR_CACHE_SIZE:
            del self._floors[next(iter(self._floors))]

    def floor_in_force(self) -> StabilityFloor | None:
        """The stability floor of the values in force if it is computed (cached), else None (no check, or not
        computed yet: after a reset to defaults or at start, until a caller computes it, e.g. on a worker)."""
        if self._stability_check is None:
            return None
        return self._floors.get(floor_key(self._values, self._link, self._link_k_floor))

    def stability_status(self) -> StabilityStatus | None:
        """lambda_crit, the guaranteed smallest eigenvalue and their ratio for the values in force (None: the
        floor is not computed yet, see floor_in_force)."""
        floor = self.floor_in_force()
        if floor is None:
            return None
        return StabilityStatus(floor.lambda_crit, floor.min_eigenvalue, floor.margin,
                               float(self._values.get("INDI_LAM_MARGIN", 1.0)),
                               float(self._values.get("INDI_LAMBDA_MIN", math.nan)),
                               self._link.delay_ticks, self._link.model_told, self._link_k_floor)

    def _floor(self, values: Mapping[str, float | int]) -> StabilityFloor:
        key = floor_key(values)
        floor = self._floors.get(key)
        if floor is None:
            floor = self.compute_floor(values)
            self.store_floor(values, floor)
        return floor

    def _cross_check(self, name: str, c: Mapping[str, float | int]) -> str | None:
        if "INDI_K_MIN" in c and "INDI_K_MAX" in c and c["INDI_K_MIN"] > c["INDI_K_MAX"]:
            return f"{name}: needs INDI_K_MIN <= INDI_K_MAX ({c['INDI_K_MIN']:g} > {c['INDI_K_MAX']:g})"
        if self._needs_floor(name) and self._stability_check is not None:
            floor = self._floor(c)
            if not floor.min_eigenvalue > floor.lambda_crit:
                return (
                    f"{name}: refused by the stability floor: min eig(Ghat G^-1) "
                    f"{floor.min_eigenvalue:.3f} <= lambda_crit {floor.lambda_crit:.3f}"
                )
            if not floor.ok:
                return (
                    f"{name}: refused: max eig(Ghat G^-1) {floor.max_eigenvalue:.2f} >= lambda_upper "
                    f"{floor.lambda_upper:.2f}, where H(s) is unstable again"
                )
            required = float(c.get("INDI_LAM_MARGIN", 1.0))
            if floor.margin < required:
                return (
                    f"{name}: refused: stability margin {floor.margin:.2f} < INDI_LAM_MARGIN {required:g} "
                    f"(guaranteed min eig {floor.min_eigenvalue:.3f}, lambda_crit {floor.lambda_crit:.3f})"
                )
            lam_min = c.get("INDI_LAMBDA_MIN")
            if lam_min is not None and lam_min <= floor.lambda_crit:
                return (
                    f"{name}: INDI_LAMBDA_MIN {lam_min:g} must exceed lambda_crit {floor.lambda_crit:.3f}"
                )
        return None

    # --- mutation -------------------------------------------------------------------------------
    def set(self, name: str, value: float, armed: bool = False) -> SetResult:
        """Apply `value` if valid; a refusal changes nothing and reports the old value."""
        if name not in self._by_name:
            return SetResult(name, False, math.nan, math.nan, f"unknown parameter {name!r}")
        old = self._values[name]
        reason = self.validate(name, value, armed)
        if reason is not None:
            return SetResult(name, False, old, old, reason)
        new = self._by_name[name].coerce(float(value))
        self._values[name] = new
        if new != old:
            self._generation += 1
        return SetResult(name, True, new, old, None)

    def load_values(self, values: Mapping[str, float]) -> list[SetResult]:
        """Apply stored values one by one (persistence); unknown or invalid entries are refused."""
        results: list[SetResult] = []
        # K bounds first in an order that keeps K_MIN <= K_MAX valid while both move.
        order = sorted(values, key=lambda n: (n != "INDI_K_MAX", n))
        if "INDI_K_MAX" in values and float(values["INDI_K_MAX"]) < float(self._values["INDI_K_MIN"]):
            order = sorted(values, key=lambda n: (n != "INDI_K_MIN", n))
        # The rules are checked one parameter at a time, so a set valid as a whole can pass through an invalid
        # intermediate in the sorted order (from the defaults INDI_LAM_REF 0.4 / INDI_KFL_MIN 0.4, the paper's 1 / 0:
        # INDI_KFL_MIN 0 first flies [0.2, 0.4], which the stability margin refuses). Refused entries are tried
        # again after the others while a pass makes progress; what is still refused then is reported.
        last: dict[str, SetResult] = {}
        pending = order
        while pending:
            refused: list[str] = []
            for n in pending:
                res = self.set(n, values[n])
                last[n] = res
                if not res.accepted:
                    refused.append(n)
            if len(refused) == len(pending):
                break
            pending = refused
        results.extend(last[n] for n in order)
        return results

    def restore(self, snapshot: Mapping[str, float | int]) -> None:
        """Put back values taken with `as_dict` from this registry (they were valid together when taken)."""
        self._values = {d.name: snapshot[d.name] for d in self._defs}
        self._generation += 1

    def reset_defaults(self) -> None:
        self._values = {d.name: d.coerce(d.default) for d in self._defs}
        self._generation += 1
