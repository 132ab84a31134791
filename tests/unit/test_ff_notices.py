"""What the flight stack says about the feed-forwards' checks (flight/ff_notices.py): each change said once, an
estimate re-announced only when it moved by more than 10 % from the one last announced."""

from __future__ import annotations

from types import SimpleNamespace

from navig8_fc.flight.ff_notices import FeedforwardNotices


def _status(arm_drops=0, arm_idents=0, v=3.0, a=30.0, wn=(120.0, 120.0), trusted=True, ff=True, indi=True):
    ff_rec = SimpleNamespace(arm_drops=arm_drops, arm_err_rad_s=0.4, arm_idents=arm_idents, arm_v_hat_rad_s=v,
                             arm_a_hat_rad_s2=a) if ff else None
    indi_rec = SimpleNamespace(act_wn_rad_s=wn, u0_model_trusted=trusted, act_innov_rms=(0.05, 30.0)) if indi else None
    return SimpleNamespace(ff=ff_rec, indi=indi_rec)


def _texts(notices) -> list[str]:
    return [n.statustext for n in notices]


def test_each_change_is_said_once_and_small_moves_are_not() -> None:
    fn = FeedforwardNotices(120.0, 3.0, 30.0)
    assert fn.notices(_status()) == []  # nothing moved
    got = _texts(fn.notices(_status(arm_drops=1)))
    assert len(got) == 1 and got[0].startswith("Arm preview off: the joints move 0.40 rad/s off the servo model")
    assert fn.notices(_status(arm_drops=1)) == []  # the same drop is not said twice
    # the servo re-identified within 10 %: not announced; beyond: announced once, the new value the reference
    assert fn.notices(_status(arm_drops=1, arm_idents=1, v=3.2)) == []
    assert _texts(fn.notices(_status(arm_drops=1, arm_idents=2, v=1.5, a=12.0))) == [
        "Arm servo identified: 1.50 rad/s, 12.0 rad/s^2"]
    assert fn.notices(_status(arm_drops=1, arm_idents=3, v=1.55, a=12.5)) == []
    # actuator bandwidth and the actuator model's trust
    assert _texts(fn.notices(_status(arm_drops=1, arm_idents=3, v=1.5, a=12.0, wn=(60.0, 119.0)))) == [
        "Actuator bandwidth identified: tilt 60 rad/s, speed 119 rad/s"]
    off = fn.notices(_status(arm_drops=1, arm_idents=3, v=1.5, a=12.0, wn=(60.0, 119.0), trusted=False))
    assert _texts(off) == ["Actuator model off (innovation 0.05 rad, 30 rad/s): flying the measured U0"]
    back = fn.notices(_status(arm_drops=1, arm_idents=3, v=1.5, a=12.0, wn=(60.0, 119.0), trusted=True))
    assert _texts(back) == ["Actuator model agrees with the measurement again: model U0"]


def test_a_new_core_counts_its_events_from_zero() -> None:
    fn = FeedforwardNotices(120.0, 3.0, 30.0)
    assert len(fn.notices(_status(arm_drops=2))) == 1
    fn.new_core()
    assert len(fn.notices(_status(arm_drops=1))) == 1  # the rebuilt core's first drop is news
