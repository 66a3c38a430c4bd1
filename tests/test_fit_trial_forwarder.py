"""The trial pool's forwarder: one bar, handed from trial to trial so every trial's progress shows."""

from __future__ import annotations

from zooctl.fit.trial_pool import _Forwarder


class _Bar:
    """What a one-bar reporter (the CLI's) is told, in order."""

    def __init__(self) -> None:
        self.calls: list[tuple] = []

    def stage(self, name: str, total: int, done: int = 0) -> None:
        self.calls.append(("stage", name, total, done))

    def step(self, terms: dict[str, float]) -> None:
        self.calls.append(("step", terms["loss"]))

    def message(self, text: str) -> None:
        self.calls.append(("message", text))


def test_the_bar_goes_to_the_other_trial_from_where_its_stage_has_got_to():
    bar = _Bar()
    fw = _Forwarder(None, bar, ["Fox", "Wolf"])
    fw._pass(0, "stage", ("stage 1", 2, 0))
    fw._pass(1, "stage", ("stage 1", 3, 0))
    fw._pass(1, "step", {"loss": 10.0})  # Wolf's steps while Fox holds the bar: counted, not drawn
    fw._pass(0, "step", {"loss": 1.0})
    fw._pass(0, "step", {"loss": 2.0})  # Fox's stage is over: Wolf takes the bar, one step in
    fw._pass(0, "stage", ("stage 2", 5, 0))  # Fox's next stage waits its turn
    fw._pass(1, "step", {"loss": 11.0})
    fw._pass(1, "step", {"loss": 12.0})  # Wolf's stage is over: back to Fox's stage 2
    fw._pass(1, "message", "done")
    assert bar.calls == [
        ("stage", "stage 1 (Fox)", 2, 0),
        ("step", 1.0),
        ("step", 2.0),
        ("stage", "stage 1 (Wolf)", 3, 1),
        ("step", 11.0),
        ("step", 12.0),
        ("stage", "stage 2 (Fox)", 5, 0),
        ("message", "[Wolf] done"),
    ]


def test_a_trial_alone_keeps_the_bar_from_stage_to_stage():
    bar = _Bar()
    fw = _Forwarder(None, bar, ["Fox", "Wolf"])
    fw._pass(0, "stage", ("stage 1", 1, 0))
    fw._pass(0, "step", {"loss": 1.0})
    fw._pass(0, "stage", ("stage 2", 1, 0))
    fw._pass(0, "step", {"loss": 2.0})
    assert [c[:2] for c in bar.calls] == [
        ("stage", "stage 1 (Fox)"),
        ("step", 1.0),
        ("stage", "stage 2 (Fox)"),
        ("step", 2.0),
    ]
