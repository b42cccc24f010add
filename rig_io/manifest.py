"""Reading and checking the ``manifest.json`` of a ``tsm-rig-log/1`` run.

The manifest is validated against a declared pydantic schema (:class:`Manifest`) with the
physical ranges of the format (rig-log-format.md section 1): identifiers that become file
names are restricted to a safe pattern, enumerations (excitation ``kind``, encoder ``unit``,
camera ``quantity`` and ``source``) are closed, numbers must be finite and within physical
ranges, and booleans are never numbers. Every reject names the key and the value.

``rig`` is a label, not a closed list: the format names the lab's two rigs (:data:`RIGS`), and
foreign rigs (importers, other labs) bring their own names. A rig name outside :data:`RIGS`
is accepted when it is a safe identifier and is recorded as given (with a log warning).
"""

from __future__ import annotations

import json
import logging
import math
import re
from collections.abc import Iterable
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
)

from rig_io.errors import RigIOError, short
from rig_io.run import FORMAT

log = logging.getLogger(__name__)

RIGS = ("tsm-bench", "bending-joint")
def excitation_name(excitation: dict[str, Any]) -> str:
    """The dataset's name for a run's excitation: its ``kind``, or, for a ``free`` run that
    carries a ``name``, that name (how a lab labels an excitation the format does not list)."""
    kind = str(excitation["kind"])
    name = excitation.get("name")
    return str(name) if kind == "free" and isinstance(name, str) and name else kind


EXCITATION_KINDS = ("sine_decay", "triangle_decay", "trapezoid_decay", "ramp", "sine",
                    "sine_decay_offset", "mixed_sine", "compensated", "free")
ENCODER_UNITS = ("mm", "deg")
VISION_QUANTITIES = ("tip_angle_deg", "output_mm")
VISION_SOURCES = ("camera", "tracker")
ENCODER_KEYS = ("unit", "counts_per_unit", "counter_bits", "input_sign", "output_sign")
LOADCELL_KEYS = ("newton_per_mv_per_v", "zero_mv_per_v", "range_n")
#: The keys that turn a load cell's mV/V into newtons (without them the cell is kept raw).
LOADCELL_CALIBRATION = ("newton_per_mv_per_v", "zero_mv_per_v")
VISION_KEYS = ("quantity", "source")

#: Identifiers that become file or folder names (``run_id``, ``rig``): a letter or digit
#: first, then letters, digits, ``.``, ``_``, ``-``; at most 128 characters; never ``..``.
SAFE_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,127}")
MAX_ID_CHARS = 128


def is_safe_identifier(value: object) -> bool:
    """Whether ``value`` may be used as a file or folder name (see :data:`SAFE_ID`)."""
    return (isinstance(value, str) and SAFE_ID.fullmatch(value) is not None
            and ".." not in value)


def _safe_id(value: str) -> str:
    if not is_safe_identifier(value):
        raise ValueError("not a safe file name (1-128 of A-Z a-z 0-9 . _ -, "
                         "a letter or digit first, no '..')")
    return value


SafeId = Annotated[str, AfterValidator(_safe_id)]


def _nonzero(value: float) -> float:
    if value == 0:
        raise ValueError("must not be 0")
    return value


def _sign(value: int) -> int:
    if value not in (1, -1):
        raise ValueError("must be 1 or -1")
    return value


_STRICT = ConfigDict(strict=True, allow_inf_nan=False, extra="allow")


class _Model(BaseModel):
    model_config = _STRICT


class Configuration(_Model):
    """The sheath shape; ``null`` where the rig does not know it."""

    curve_angle_deg: Annotated[float, Field(ge=0.0, le=360.0)] | None = None
    radius_mm: Annotated[float, Field(gt=0.0, le=1e4)] | None = None


class MixedTerm(_Model):
    """One ``{amplitude, frequency_hz, phase_rad}`` term; frequency 0 is a constant term
    (``amplitude * sin(phase_rad)``), which a recorder uses to start the motion at zero."""

    amplitude: Annotated[float, Field(ge=-1e4, le=1e4)] | None = None
    frequency_hz: Annotated[float, Field(ge=0.0, le=1e4)] | None = None
    phase_rad: Annotated[float, Field(ge=-1e3, le=1e3)] | None = None


class Excitation(_Model):
    """``kind`` and the parameters of format section 1 (checked where present; others free)."""

    kind: Literal["sine_decay", "triangle_decay", "trapezoid_decay", "ramp", "sine",
                  "sine_decay_offset", "mixed_sine", "compensated", "free"]
    amplitudes_mm: Annotated[list[Annotated[float, Field(ge=0.0, le=1e4)]],
                             Field(max_length=10_000)] | None = None
    periods_per_amplitude: Annotated[float, Field(gt=0.0, le=1e6)] | None = None
    frequency_hz: Annotated[float, Field(gt=0.0, le=1e4)] | None = None
    slope_mm_s: Annotated[float, Field(gt=0.0, le=1e5)] | None = None
    dwell_s: Annotated[float, Field(ge=0.0, le=1e6)] | None = None
    velocity_mm_s: Annotated[float, Field(ge=-1e5, le=1e5)] | None = None
    stroke_mm: Annotated[float, Field(ge=-1e4, le=1e4)] | None = None
    amplitude: Annotated[float, Field(ge=-1e6, le=1e6)] | None = None
    offset: Annotated[float, Field(ge=-1e6, le=1e6)] | None = None
    duration_s: Annotated[float, Field(gt=0.0, le=1e7)] | None = None
    terms: Annotated[list[MixedTerm], Field(max_length=1000)] | None = None
    target: Excitation | None = None
    model: str | None = None
    #: What a ``free`` run is called in the dataset (the format has no kind for it).
    name: SafeId | None = None


class Encoder(_Model):
    """``channels.encoder``; every key optional here, required by :func:`check_manifest`
    for run folders (bags carry SI values, where only ``unit`` applies)."""

    unit: Literal["mm", "deg"] | None = None
    counts_per_unit: Annotated[float, Field(ge=1e-2, le=1e9)] | None = None
    counter_bits: Annotated[int, Field(ge=2, le=63)] | None = None
    input_sign: Annotated[int, AfterValidator(_sign)] | None = None
    output_sign: Annotated[int, AfterValidator(_sign)] | None = None


class LoadCell(_Model):
    newton_per_mv_per_v: Annotated[float, Field(ge=-1e6, le=1e6),
                                   AfterValidator(_nonzero)] | None = None
    zero_mv_per_v: Annotated[float, Field(ge=-1e3, le=1e3)] | None = None
    range_n: Annotated[float, Field(gt=0.0, le=1e6)] | None = None


class LoadCells(_Model):
    input: LoadCell | None = None
    output: LoadCell | None = None


class Vision(_Model):
    """``channels.camera`` / ``channels.tracker``."""

    quantity: Literal["tip_angle_deg", "output_mm"] | None = None
    source: Literal["camera", "tracker"] | None = None
    nominal_latency_ms: Annotated[float, Field(ge=0.0, le=1e4)] | None = None
    rate_hz: Annotated[float, Field(gt=0.0, le=1e6)] | None = None


class Channels(_Model):
    encoder: Encoder | None = None
    loadcell: LoadCells | None = None
    camera: Vision | None = None
    tracker: Vision | None = None


class Manifest(_Model):
    """The manifest of format section 1 (unknown keys are kept, not checked)."""

    format: Literal["tsm-rig-log/1"]
    run_id: SafeId
    rig: SafeId
    started_at: str | None = None
    configuration: Configuration
    excitation: Excitation
    channels: Channels
    notes: str | None = None


def parse_manifest(text: str, *, run: str | None, file: str) -> dict[str, Any]:
    """Parse manifest JSON text; a parse error names the line."""
    try:
        manifest = json.loads(text)
    except json.JSONDecodeError as err:
        raise RigIOError(f"manifest is not valid JSON: {err.msg} (column {err.colno})",
                         run=run, file=file, row=err.lineno) from None
    except RecursionError:
        raise RigIOError("manifest is nested too deeply", run=run, file=file) from None
    if not isinstance(manifest, dict):
        raise RigIOError("manifest is not a JSON object", run=run, file=file)
    return manifest


_TOO_DEEP = object()


def _non_finite(value: Any, path: str, depth: int = 0) -> tuple[str, Any] | None:
    """The first NaN/Infinity anywhere in the manifest (JSON has neither; Python accepts them)."""
    if isinstance(value, float) and not math.isfinite(value):
        return path, value
    if depth > 50:
        return path, _TOO_DEEP
    if isinstance(value, dict):
        for k, v in value.items():
            hit = _non_finite(v, f"{path}.{k}" if path else str(k), depth + 1)
            if hit is not None:
                return hit
    elif isinstance(value, list):
        for i, v in enumerate(value):
            hit = _non_finite(v, f"{path}[{i}]", depth + 1)
            if hit is not None:
                return hit
    return None


def _key(loc: tuple[int | str, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif not part.startswith(("function-", "constrained-", "literal[")):
            out += f".{part}" if out else part
    return out or "<manifest>"


def _describe(err: ValidationError) -> tuple[str, str]:
    """(key, reason) of the first error of a pydantic validation."""
    errors = err.errors(include_url=False)
    first = errors[0]
    key = _key(tuple(first["loc"]))
    kind = first["type"]
    if kind == "missing":
        reason = f"manifest has no {key!r}"
    elif kind == "literal_error":
        reason = f"{key} is {short(first['input'])}: {first['msg'].lower()}"
    else:
        msg = str(first["msg"]).removeprefix("Value error, ")
        reason = f"{key} = {short(first['input'])}: {msg}"
    more = len(errors) - 1
    if more:
        reason += f" (and {more} more problem{'s' if more > 1 else ''})"
    return key, reason


def validate_manifest(manifest: dict[str, Any], *, file: str,
                      run_hint: str | None = None) -> Manifest:
    """The manifest checked against :class:`Manifest`; :class:`RigIOError` naming key and value."""
    run = manifest.get("run_id", run_hint)
    run_s = run if is_safe_identifier(run) else run_hint
    fmt = manifest.get("format")
    if fmt != FORMAT:
        raise RigIOError(f"unknown format {short(fmt)} (expected {FORMAT!r})", run=run_s,
                         file=file, key="format")
    hit = _non_finite(manifest, "")
    if hit is not None and hit[1] is _TOO_DEEP:
        raise RigIOError("manifest is nested more than 50 levels deep", run=run_s, file=file,
                         key=hit[0][:60])
    if hit is not None:
        raise RigIOError(f"{hit[0]} is {hit[1]!r}: manifest values must be finite numbers",
                         run=run_s, file=file, key=hit[0])
    try:
        model = Manifest.model_validate(manifest)
    except ValidationError as err:
        key, reason = _describe(err)
        raise RigIOError(reason, run=run_s, file=file, key=key) from None
    except RecursionError:
        raise RigIOError("manifest is nested too deeply", run=run_s, file=file) from None
    if model.rig not in RIGS:
        log.warning("run %r: rig %r is not one of the lab's rigs (%s); recorded as given",
                    model.run_id, model.rig, ", ".join(RIGS))
    return model


def check_manifest(manifest: dict[str, Any], *, file: str, streams: Iterable[str],
                   si_units: bool = False, run_hint: str | None = None) -> str:
    """Check the manifest (schema, ranges, the keys ingest needs); return the run id.

    ``streams`` names the streams present (``encoder``, ``loadcell``, ``camera``, ...): their
    channel descriptions must be there. ``si_units`` (bags) relaxes the encoder and load-cell
    calibration keys, which do not apply to values already in SI units (they are still
    range-checked where present).
    """
    model = validate_manifest(manifest, file=file, run_hint=run_hint)
    run_s = model.run_id
    names = set(streams)
    channels = manifest["channels"]
    if not si_units:
        enc = channels.get("encoder")
        if not isinstance(enc, dict):
            raise RigIOError("manifest has no channels.encoder", run=run_s, file=file,
                             key="channels.encoder")
        _need(enc, ENCODER_KEYS, "channels.encoder", run_s, file)
        if "loadcell" in names:
            # A cell without its zero and gain is kept raw and flagged (rig_io.calibrate), never
            # turned into newtons; half a calibration is a mistake, not a choice.
            cells = channels.get("loadcell") or {}
            for side in ("input", "output"):
                cell = cells.get(side) or {}
                if any(cell.get(k) is not None for k in LOADCELL_CALIBRATION):
                    # calibrated: all of it, and the range its saturation check needs
                    _need(cell, LOADCELL_KEYS, f"channels.loadcell.{side}", run_s, file)
    for vision in ("camera", "tracker"):
        if vision in names:
            ch = channels.get(vision)
            if not isinstance(ch, dict):
                raise RigIOError(f"{vision} stream present but no channels.{vision}",
                                 run=run_s, file=file, key=f"channels.{vision}")
            _need(ch, VISION_KEYS, f"channels.{vision}", run_s, file)
    return run_s


def _need(section: dict[str, Any], keys: Iterable[str], where: str, run: str | None,
          file: str) -> None:
    missing = [k for k in keys if section.get(k) is None]
    if missing:
        raise RigIOError(f"{where} lacks {', '.join(missing)}", run=run, file=file,
                         key=f"{where}.{missing[0]}")
