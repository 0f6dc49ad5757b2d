"""The machine description file (machining_envs.core.machine)."""

import dataclasses
from pathlib import Path

import gymnasium as gym
import pytest

import machining_envs  # noqa: F401
from machining_envs.core.actuation import SHOPFLOOR_ACTUATION, SHOPFLOOR_OVERRIDE
from machining_envs.core.machine import SHOPFLOOR_MACHINE, Machine, load_machine
from machining_envs.core.sensors import PowerSensor
from tests.helpers import refuses_file

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "my_cnc.yml"


def test_example_file_is_the_shopfloor_machine():
    m = load_machine(EXAMPLE)
    assert m.name == "my_lathe"
    assert m.actuation == SHOPFLOOR_ACTUATION
    assert m.spindle_power_W == SHOPFLOOR_MACHINE.spindle_power_W
    assert m.power_sensor is None
    assert m.feed_override == SHOPFLOOR_OVERRIDE == SHOPFLOOR_MACHINE.feed_override
    assert m.as_dict() == {**SHOPFLOOR_MACHINE.as_dict(), "name": "my_lathe"}
    assert load_machine(EXAMPLE).as_dict() == {**m.as_dict()}
    assert Machine(**{**m.as_dict(), "name": "x"}).actuation == m.actuation


def test_env_kwargs_per_env(tmp_path):
    f = tmp_path / "m.yml"
    f.write_text(
        "actuation: {delay_steps: 1}\nspindle_power_W: 3000\npower_sensor: {quantum_W: 2}\n"
    )
    m = load_machine(f)
    assert m.name == "m"
    assert m.power_sensor == PowerSensor(quantum_W=2.0)
    for env_id in ("machining_envs/Turning-v0", "machining_envs/EndMilling-v0"):
        kw = m.env_kwargs(env_id)
        assert ("spindle_power_W" in kw) == env_id.endswith("Turning-v0")
        assert kw["power_sensor"]["quantum_W"] == 2.0
        env = gym.make(env_id, **kw)
        env.reset(seed=0)
        assert env.unwrapped.actuation.delay_steps == 1
        assert env.unwrapped.power_sensor.quantum_W == 2.0
    assert Machine("ideal").env_kwargs("machining_envs/Turning-v0") == {}


@pytest.mark.parametrize(
    "text, match",
    [
        ("speed: 3\n", "unknown keys"),
        ("actuation: {delay_steps: 99}\n", "delay_steps"),
        ("spindle_power_W: -1\n", "spindle_power_W"),
        ("power_sensor: {idle_W: -5}\n", "idle_W"),
        ("- 1\n- 2\n", "mapping"),
        ("actuation: {delay: 1}\n", "unknown settings"),
        ("feed_override: {quantum: 2}\n", "quantum"),
    ],
)
def test_bad_files_name_the_key(tmp_path, text, match):
    refuses_file(tmp_path / "bad.yml", text, load_machine, ValueError, match)


def test_missing_file():
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_machine("/nonexistent/machine.yml")


def test_spread_around_the_description():
    variants = SHOPFLOOR_MACHINE.spread()
    assert {v.delay_steps for v in variants} == {1, 2, 3}
    assert {v.max_rate_per_s for v in variants} == {0.4, 0.625}
    assert all(v.quantum == 0.01 for v in variants)


def test_contouring_feed_gets_the_feed_override():
    """ContouringFeed-v0's override has its own handling (10 ms decisions, range [0, 2]);
    without one it gets the machine's actuation."""
    kw = SHOPFLOOR_MACHINE.env_kwargs("machining_envs/ContouringFeed-v0")
    assert kw == {"actuation": dataclasses.asdict(SHOPFLOOR_OVERRIDE)}
    assert (
        SHOPFLOOR_MACHINE.env_kwargs("machining_envs/EndMilling-v0")["actuation"]["max_rate_per_s"]
        == SHOPFLOOR_ACTUATION.max_rate_per_s
    )
    plain = Machine("m", SHOPFLOOR_ACTUATION)
    assert plain.env_kwargs("machining_envs/ContouringFeed-v0") == {
        "actuation": dataclasses.asdict(SHOPFLOOR_ACTUATION)
    }
