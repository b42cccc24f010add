"""Reading and checking the ``manifest.json`` of a ``tsm-rig-log/1`` run."""

from __future__ import annotations

import json
from collections.abc import Iterable
from typing import Any

from rig_io.errors import RigIOError
from rig_io.run import FORMAT

RIGS = ("tsm-bench", "bending-joint")
EXCITATION_KINDS = ("sine_decay", "triangle_decay", "trapezoid_decay", "ramp", "sine",
                    "sine_decay_offset", "mixed_sine", "compensated", "free")
ENCODER_KEYS = ("unit", "counts_per_unit", "counter_bits", "input_sign", "output_sign")
LOADCELL_KEYS = ("newton_per_mv_per_v", "zero_mv_per_v", "range_n")
VISION_KEYS = ("quantity", "source")


def parse_manifest(text: str, *, run: str | None, file: str) -> dict[str, Any]:
    """Parse manifest JSON text; a parse error names the line."""
    try:
        manifest = json.loads(text)
    except json.JSONDecodeError as err:
        raise RigIOError(f"manifest is not valid JSON: {err.msg} (column {err.colno})",
                         run=run, file=file, row=err.lineno) from None
    if not isinstance(manifest, dict):
        raise RigIOError("manifest is not a JSON object", run=run, file=file)
    return manifest


def check_manifest(manifest: dict[str, Any], *, file: str, streams: Iterable[str],
                   si_units: bool = False, run_hint: str | None = None) -> str:
    """Check the keys ingest needs; return the run id.

    ``streams`` names the streams present (``encoder``, ``loadcell``, ``camera``, ...): their
    channel descriptions must be there. ``si_units`` (bags) relaxes the encoder and load-cell
    calibration keys, which do not apply to values already in SI units.
    """
    run = manifest.get("run_id", run_hint)
    run_s = str(run) if run is not None else None
    fmt = manifest.get("format")
    if fmt != FORMAT:
        raise RigIOError(f"unknown format {fmt!r} (expected {FORMAT!r})", run=run_s, file=file)
    if not isinstance(manifest.get("run_id"), str) or not manifest["run_id"]:
        raise RigIOError("manifest has no 'run_id' string", run=run_s, file=file)
    for key in ("rig", "configuration", "excitation", "channels"):
        if key not in manifest:
            raise RigIOError(f"manifest has no {key!r}", run=run_s, file=file)
    config = manifest["configuration"]
    if not isinstance(config, dict):
        raise RigIOError("manifest 'configuration' is not an object", run=run_s, file=file)
    for key in ("curve_angle_deg", "radius_mm"):
        value = config.get(key)
        if value is not None and not isinstance(value, int | float):
            raise RigIOError(f"configuration.{key} must be a number or null, got {value!r}",
                             run=run_s, file=file)
    exc = manifest["excitation"]
    if not isinstance(exc, dict) or not isinstance(exc.get("kind"), str):
        raise RigIOError("manifest 'excitation' has no 'kind'", run=run_s, file=file)
    channels = manifest["channels"]
    if not isinstance(channels, dict):
        raise RigIOError("manifest 'channels' is not an object", run=run_s, file=file)
    names = set(streams)
    if not si_units:
        enc = channels.get("encoder")
        if not isinstance(enc, dict):
            raise RigIOError("manifest has no channels.encoder", run=run_s, file=file)
        _need(enc, ENCODER_KEYS, "channels.encoder", run_s, file)
        if int(enc["counter_bits"]) < 2 or int(enc["counter_bits"]) > 63:
            raise RigIOError(f"channels.encoder.counter_bits {enc['counter_bits']!r} "
                             "out of range 2..63", run=run_s, file=file)
        if float(enc["counts_per_unit"]) == 0:
            raise RigIOError("channels.encoder.counts_per_unit is 0", run=run_s, file=file)
        if "loadcell" in names:
            cells = channels.get("loadcell")
            if not isinstance(cells, dict):
                raise RigIOError("loadcell stream present but no channels.loadcell",
                                 run=run_s, file=file)
            for side in ("input", "output"):
                cell = cells.get(side)
                if not isinstance(cell, dict):
                    raise RigIOError(f"no channels.loadcell.{side}", run=run_s, file=file)
                _need(cell, LOADCELL_KEYS, f"channels.loadcell.{side}", run_s, file)
    for vision in ("camera", "tracker"):
        if vision in names:
            ch = channels.get(vision)
            if not isinstance(ch, dict):
                raise RigIOError(f"{vision} stream present but no channels.{vision}",
                                 run=run_s, file=file)
            _need(ch, VISION_KEYS, f"channels.{vision}", run_s, file)
    return str(manifest["run_id"])


def _need(section: dict[str, Any], keys: Iterable[str], where: str, run: str | None,
          file: str) -> None:
    missing = [k for k in keys if k not in section]
    if missing:
        raise RigIOError(f"{where} lacks {', '.join(missing)}", run=run, file=file)
