"""Regenerate the committed sample runs (run from the repository root).

    .venv/bin/python data/samples/regenerate.py

The samples are one short virtual-rig run (90 deg / 30 mm, one 0.5 Hz period of a 6 mm sine,
camera on) as a run folder with gzipped CSV and the same run as a rosbag1 file. They are
golden files: `tests/rig_io/test_committed_samples.py` reads them as they are on disk, so a
reader change that breaks files already written by the rig is caught. Regenerate only when
the format itself changes.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from rig_io.bag import write_bag
from rig_io.folder import write_run_folder
from rig_io.virtual import simulate_run

HERE = Path(__file__).resolve().parent
RUN_ID = "sample_phi090_r030_sine_0001"


def main() -> None:
    run = simulate_run(
        curve_angle_deg=90.0, radius_mm=30.0,
        excitation={"kind": "sine", "amplitude": 6.0, "offset": 0.0, "frequency_hz": 0.5,
                    "duration_s": 2.0},
        seed=2026, run_id=RUN_ID,
    )
    for old in (HERE / "folder", HERE / "rosbag1"):
        shutil.rmtree(old, ignore_errors=True)
    write_run_folder(run, HERE / "folder", compress=True)
    (HERE / "rosbag1").mkdir()
    write_bag(run, HERE / "rosbag1" / f"{RUN_ID}.bag", storage="rosbag1")


if __name__ == "__main__":
    main()
