"""Settings that left evcd (evcd.utils.removed): refused where they are set or were used, with the last
commit that has them; dropped where an old config holds them at the value that did nothing."""

from __future__ import annotations

import pytest

from evcd.utils.removed import REMOVED, check_overrides, drop_removed


@pytest.mark.parametrize(
    "override",
    ["learner.rule_prior=true", "+learner.in_turn=false", "~learner.lr_end", "agent.switch_margin_s=60"],
)
def test_a_removed_setting_on_the_command_line_is_refused_in_one_line_naming_the_commit(override):
    with pytest.raises(ValueError) as info:
        check_overrides(["evs=400", override])
    message = str(info.value)
    key = override.lstrip("+~").partition("=")[0]
    assert message.startswith(f"{key}=") and f"commit {REMOVED[key].commit}" in message
    assert "\n" not in message


def test_settings_that_stay_pass():
    check_overrides(["learner.lr=0.01", "agent=central", "train.validation.select_best=true", "-m"])


def test_an_old_config_loses_its_inert_removed_settings_and_keeps_the_rest():
    old = {"seed": 0, "learner": {"lr": 0.001, "rule_prior": False, "rule_prior_bound_s": None,
                                  "lr_decay_steps": 10000, "switch_margin_s": 0.0},
           "train": {"validation": {"every": 0, "at_start": False}}}  # fmt: skip
    assert drop_removed(old) == {"seed": 0, "learner": {"lr": 0.001}, "train": {"validation": {"every": 0}}}
    assert old["learner"]["rule_prior"] is False  # the input is not changed


@pytest.mark.parametrize(
    ("config", "named"),
    [({"learner": {"rule_prior": True}}, "learner.rule_prior=True"),
     ({"learner": {"lr_decay_steps": 500}}, "learner.lr_decay_steps=500"),
     ({"train": {"validation": {"at_start": True}}}, "train.validation.at_start=True")],
)  # fmt: skip
def test_an_old_config_that_used_a_removed_setting_is_refused(config, named):
    with pytest.raises(ValueError, match=rf"^{named}: this setting left evcd; commit c467250"):
        drop_removed(config)


def test_a_prefix_names_keys_below_it():
    assert drop_removed({"lr": 0.1, "in_turn": False}, "learner.") == {"lr": 0.1}
    with pytest.raises(ValueError, match=r"learner\.in_turn=True"):
        drop_removed({"in_turn": True}, "learner.")
    assert drop_removed({"in_turn": True}) == {"in_turn": True}  # not a key of conf/train.yaml's layout
