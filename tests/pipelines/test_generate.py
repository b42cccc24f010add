"""Stage ``generate``: config composition, writing a campaign in every format, never rewriting
raw runs, the Hydra CLI."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from pipelines.common import CONF_DIR
from pipelines.core.generate import (
    CAMPAIGN_FILE,
    GenerateError,
    campaign_specs,
    run_generate,
    specs_from_config,
)
from rig_io.bag import read_bag
from rig_io.folder import read_run_folder
from rig_io.virtual import EFFECT_NAMES, standard_campaign

REPO = Path(__file__).resolve().parents[2]
SHORT = [{"kind": "sine_decay", "amplitudes_mm": [3.0], "periods_per_amplitude": 1,
          "frequency_hz": 1.0}]


def _compose(overrides: list[str] | None = None):  # type: ignore[no-untyped-def]
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose(config_name="generate", overrides=overrides or [])


def _small(**kw: object) -> list[dict[str, object]]:
    return campaign_specs(seed=0, curve_angles_deg=[15, 90], radii_mm=[30], excitations=SHORT,
                          **kw)  # type: ignore[arg-type]


def test_default_config_is_the_standard_campaign() -> None:
    cfg = _compose()
    assert cfg.format == "folder" and cfg.out.endswith("data/raw/virtual")
    assert dict(cfg.effects) == dict.fromkeys(EFFECT_NAMES, 0.0)
    specs = specs_from_config(cfg)
    assert len(specs) == 120
    assert [s["run_id"] for s in specs] == [s["run_id"] for s in standard_campaign(0)]
    assert json.dumps(specs)  # plain containers, no OmegaConf nodes
    other = specs_from_config(_compose(["campaign=quick", "effects=drift_only",
                                        "rig=bending_joint", "campaign.seed=3"]))
    assert len(other) == 10 and all(s["effects"]["drift"] == 1.0 for s in other)
    assert all(s["rig"] == "bending-joint" for s in other)
    assert [s["seed"] for s in other] != [s["seed"] for s in standard_campaign(0)[:10]]
    cath = specs_from_config(_compose(["rig=bending_joint_catheter", "campaign=quick"]))
    assert cath[0]["params"]["section_diameter_mm"] == 6.5


def test_writes_valid_run_folders_and_never_rewrites_them(tmp_path: Path) -> None:
    out = tmp_path / "raw"
    specs = _small()
    rep = run_generate(specs, out, n_jobs=1, progress=False)
    assert rep["written"] == sorted(s["run_id"] for s in specs) and rep["skipped"] == []
    for s in specs:
        run = read_run_folder(out / s["run_id"])  # the format's reader and checks
        assert run.manifest["excitation"] == s["excitation"]
    book = json.loads((out / CAMPAIGN_FILE).read_text())
    assert set(book["runs"]) == {s["run_id"] for s in specs}
    stamp = (out / specs[0]["run_id"] / "encoder.csv").stat().st_mtime_ns
    again = run_generate(specs, out, n_jobs=1, progress=False)
    assert again["written"] == [] and len(again["skipped"]) == 2
    assert (out / specs[0]["run_id"] / "encoder.csv").stat().st_mtime_ns == stamp
    changed = _small(effects={"drift": 1.0})
    with pytest.raises(GenerateError, match="never rewritten"):
        run_generate(changed, out, n_jobs=1, progress=False)
    rep = run_generate(changed, out, n_jobs=1, progress=False, overwrite=True)
    assert len(rep["written"]) == 2
    assert "drift" in read_run_folder(out / specs[0]["run_id"]).manifest["notes"]


@pytest.mark.parametrize("fmt", ["rosbag1", "mcap", "sqlite3"])
def test_writes_bags(tmp_path: Path, fmt: str) -> None:
    specs = _small()[:1]
    run_generate(specs, tmp_path, fmt=fmt, n_jobs=1, progress=False)
    rid = specs[0]["run_id"]
    path = tmp_path / (f"{rid}.bag" if fmt == "rosbag1" else rid)
    if fmt != "rosbag1":
        assert (path / "metadata.yaml").is_file()
    back = read_bag(path)
    assert back.manifest["run_id"] == rid and len(back.encoder) == 101


def test_parallel_workers_write_the_same_runs(tmp_path: Path) -> None:
    specs = _small()[1:]  # one run in this process, the same and another in two workers
    run_generate(specs, tmp_path / "one", n_jobs=1, progress=False)
    run_generate(_small(), tmp_path / "two", n_jobs=2, progress=False)
    for s in specs:
        a = (tmp_path / "one" / s["run_id"] / "loadcell.csv").read_bytes()
        b = (tmp_path / "two" / s["run_id"] / "loadcell.csv").read_bytes()
        assert a == b


def test_bad_options_are_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(GenerateError, match="format must be one of"):
        run_generate(_small(), tmp_path, fmt="hdf5", progress=False)
    with pytest.raises(GenerateError, match="run folders only"):
        run_generate(_small(), tmp_path, fmt="mcap", compress=True, progress=False)


def test_cli(tmp_path: Path) -> None:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(REPO / ".venv" / "numba-cache"))
    # the five excitation kinds, each a couple of seconds long: the command line is tested
    # here, the runs' content by the tests above
    short = ("[{kind:sine_decay,amplitudes_mm:[3.0],periods_per_amplitude:1,frequency_hz:0.5},"
             "{kind:triangle_decay,amplitudes_mm:[3.0],periods_per_amplitude:1,slope_mm_s:6.0},"
             "{kind:trapezoid_decay,amplitudes_mm:[3.0],periods_per_amplitude:1,slope_mm_s:6.0,"
             "dwell_s:0.5},{kind:mixed_sine,terms:[{amplitude:3.0,frequency_hz:0.5,"
             "phase_rad:0.0}],duration_s:2.0},{kind:band_random,amplitude_mm:3.0,"
             "band_hz:[0.1,0.5],duration_s:2.0,seed:11}]")
    cmd = [sys.executable, "-m", "pipelines.generate", "campaign=quick",
           "campaign.curve_angles_deg=[45]", f"campaign.excitations={short}", "n_jobs=1",
           "progress=false", "compress=true", f"out={tmp_path / 'raw'}",
           f"hydra.run.dir={tmp_path / 'hydra'}"]
    proc = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "5 runs written" in proc.stdout
    folders = sorted(p.name for p in (tmp_path / "raw").iterdir() if p.is_dir())
    assert folders == ["phi045_r030_band_random_0005", "phi045_r030_mixed_sine_0004",
                       "phi045_r030_sine_decay_0001", "phi045_r030_trapezoid_decay_0003",
                       "phi045_r030_triangle_decay_0002"]
    assert (tmp_path / "raw" / folders[0] / "loadcell.csv.gz").is_file()
    bad = subprocess.run(cmd[:3] + ["format=xml", f"out={tmp_path / 'x'}",
                                    f"hydra.run.dir={tmp_path / 'hydra2'}"],
                         cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "format must be one of" in bad.stderr
