"""sim.capacity and twin.config.load_checked_config: a mixer either becomes a twin or is refused at once
(issue 42): the particle bounds (the live twin's below every other twin's), the DEM's step, ``--fill``."""

from __future__ import annotations

import pytest

from sim.capacity import LIVE_MAX_PARTICLES, MAX_PARTICLES, check_twin, twin_particles
from sim.errors import SimError
from sim.mixer import parse_mixer
from tests.cli import assert_one_line_error, cli
from twin.config import load_checked_config


def _mixer_toml(drum_mm: float, particle_mm: float, amount: str, shape: str = "disc") -> str:
    """A monolayer drum of the default classes (red and blue), both of one size and shape."""
    return f"[drum]\ndiameter_mm = {drum_mm}\nmonolayer = true\n" + "".join(
        f'\n[[particles]]\nname = "{n}"\nshape = "{shape}"\ndiameter_mm = {particle_mm}\n{amount}\n'
        for n in ("red", "blue"))


def _mixer(drum_mm: float, particle_mm: float, amount: str, shape: str = "disc"):
    import tomllib

    return parse_mixer(tomllib.loads(_mixer_toml(drum_mm, particle_mm, amount, shape)), ["red", "blue"])


def test_the_live_twin_holds_fewer_particles_than_an_offline_one():
    half = LIVE_MAX_PARTICLES // 2
    at = _mixer(1500, 8.8, f"count = {half}")
    over = _mixer(1500, 8.8, f"count = {half + 1}")
    assert twin_particles(at) == LIVE_MAX_PARTICLES
    assert check_twin(at, live=True) == "dem" and check_twin(over) == "dem"
    with pytest.raises(SimError, match=f"{2 * half + 2} particles; a live twin holds at most {LIVE_MAX_PARTICLES}"):
        check_twin(over, live=True, source="config x")
    big = _mixer(10_000, 8.8, f"count = {MAX_PARTICLES // 2 + 1}")
    for live in (False, True):  # beyond every twin's bound: the same refusal, live or not
        with pytest.raises(SimError, match=f"{MAX_PARTICLES + 2} particles; a twin holds at most {MAX_PARTICLES}"):
            check_twin(big, live=live)


def test_a_bed_given_by_shares_is_counted_before_it_is_bounded():
    m = _mixer(2000, 4.0, "share = 0.5")  # a 2 m drum half full of 4 mm discs: about 100,000
    assert twin_particles(m) > MAX_PARTICLES
    with pytest.raises(SimError, match="a twin holds at most"):
        check_twin(m)


def test_discs_too_light_for_the_dems_step_are_refused_with_their_size_and_pymunk_shapes_are_not_stepped():
    with pytest.raises(SimError, match=r"config x: the DEM cannot step discs this light \(the smallest 0.5 mm"):
        check_twin(_mixer(250, 0.5, "count = 50"), source="config x")
    assert check_twin(_mixer(250, 2.0, "count = 50")) == "dem"
    assert check_twin(_mixer(250, 0.5, "count = 50", shape="cut_disc")) == "pymunk"


def test_run_refuses_a_config_over_the_live_bound_that_sim_whatif_and_calibrate_accept(tmp_path):
    cfg = tmp_path / "rig.toml"
    cfg.write_text(_mixer_toml(1500, 8.8, f"count = {LIVE_MAX_PARTICLES}"))  # 2x the live bound
    assert load_checked_config(cfg).mixer.particles[0].count == LIVE_MAX_PARTICLES
    r = cli("run", "--no-dashboard", "--duration", "1", "--speed", "10", "--log", tmp_path / "run", "--config", cfg)
    assert_one_line_error(r, f"{2 * LIVE_MAX_PARTICLES} particles", f"live twin holds at most {LIVE_MAX_PARTICLES}")
    assert not (tmp_path / "run").exists()  # refused before the run log


def test_whatif_fill_that_grows_a_bed_by_shares_past_the_bound_is_refused(tmp_path):
    cfg = tmp_path / "rig.toml"
    cfg.write_text(_mixer_toml(2000, 8.8, "share = 0.5").replace("monolayer = true", "monolayer = true\nfill = 0.3"))
    n = load_checked_config(cfg).mixer
    assert twin_particles(n) < MAX_PARTICLES  # at its own fill
    r = cli("whatif", "--config", cfg, "--fill", "0.8", "--rpm", "5", "--duration", "0.5", "--workers", "1")
    assert_one_line_error(r, "--fill 0.8", f"a twin holds at most {MAX_PARTICLES}")
