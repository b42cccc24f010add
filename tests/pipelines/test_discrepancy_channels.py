"""Every channel the runs carry is used: a load-cell stream that ends a few samples before the
encoder's (written by the clean-room rig-log writer, ``tests/cleanroom/riglog.py``) is filled
and reported, not dropped for one missing sample; a stream with a long hole is dropped with
the reason."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from pipelines.core.ingest import run_ingest
from pipelines.discrepancy_data import channel_values, runs_from_dataset
from rig_io.dataset import read_dataset, read_runs
from tests.cleanroom import riglog


def test_a_ragged_load_cell_end_is_filled_and_reported(tmp_path: Path) -> None:
    src, out = tmp_path / "raw", tmp_path / "out"
    ex = riglog.make_excitation("sine_decay", duration_scale=0.2)
    y, t_in, t_out = riglog.simple_tsm_plant(ex.u)
    riglog.write_run_folder(src, "lc", ex.t_s, ex.u, y, excitation=ex.manifest,
                            loadcell=(t_in, t_out), faults=["ragged_loadcell_end"])
    assert run_ingest(src, out, progress=False)["n_accepted"] == 1
    rows = read_dataset(out)
    assert rows["tension_in_n"].isna().sum() > 0  # what ingest leaves at the ragged end
    channels: dict[str, dict[str, str]] = {}
    (run,) = runs_from_dataset(rows, read_runs(out), identify_excitations=["sine_decay"],
                               channels=channels)
    assert run.tension is not None and np.isfinite(run.tension).all()
    assert run.tension_out is not None
    assert "filled by interpolation" in channels["lc"]["tension_in_n"]


def test_a_long_hole_drops_the_channel_with_its_reason() -> None:
    t = np.arange(1000) * 0.01
    values = np.sin(t)
    values[400:460] = np.nan
    arr, note = channel_values(pd.Series(values), t)
    assert arr is None and note.startswith("dropped: 60 of 1000 samples missing")
    values[400:460] = np.sin(t[400:460])
    values[-2:] = np.nan
    arr, note = channel_values(pd.Series(values), t)
    assert arr is not None and arr[-1] == arr[-3] and "longest gap 2" in note
