"""The local dynamic model's parameter file (spec §11.1, §11.5): the channels, the static maps, the linear
blocks and the fit summary as pydantic models (:class:`HWModelFile`, schema ``hw-model``), reading and
writing it, and its MATLAB export (§11.5.2).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Annotated, Any, Final, Literal, Sequence, Union, get_args

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from haptify.codes import Code
from haptify.metrics.metric_definitions import FamilyParameters, load_parameters
from haptify.versions import SPEC_VERSION

#: The metric family (``schemas/<v>/metrics/dynamics.json``) every parameter of the model comes from.
FAMILY = "dynamics"


#: The static maps a fit may use (spec §11.2): breakpoint tables or none.
MapType = Literal["piecewise_linear", "unit_gain"]
MAP_TYPES: Final = get_args(MapType)


class FitParameters(FamilyParameters):
    """The fitting rules of ``metrics/dynamics.json`` (spec §11.4): model orders and delay, the static maps
    and their breakpoints, the initialisation and the Levenberg–Marquardt schedule."""

    nb: int
    nf: int
    nk: int
    input_map: MapType
    output_map: MapType
    breakpoints: int
    breakpoint_quantiles: tuple[float, float]
    initial_pole: float
    ridge: float
    max_iterations: int
    tolerance: float
    lm_damping: tuple[float, float, float, float]
    stability_radius: float


class DynamicsParameters(FitParameters):
    """The parameters of ``metrics/dynamics.json`` (spec chapter 11): the fitting rules, the trials' sample rate
    and length, and the distance's windows and scales, in the units its definition file states."""

    sample_rate_hz: float
    min_training_s: float
    window_s: float
    segment_s: float
    R_p: float
    R_v: float
    R_a: float
    R_theta: float


#: The dynamics family's parameters, loaded and checked once at import (spec §0.3).
PARAMETERS = load_parameters(FAMILY, DynamicsParameters)


MODEL_FORMAT: Final = "haptify-hw-model"

#: The model's 13 inputs and 6 outputs (spec §11.1), in this order.
INPUT_NAMES = ("qw", "qx", "qy", "qz", "px", "py", "pz", "vx", "vy", "vz", "ax", "ay", "az")
INPUT_UNITS = ("1",) * 4 + ("m",) * 3 + ("m/s",) * 3 + ("m/s^2",) * 3
OUTPUT_NAMES = ("fx", "fy", "fz", "tx", "ty", "tz")
OUTPUT_UNITS = ("N",) * 3 + ("N*m",) * 3


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


def _all_finite(values: Sequence[float], what: str) -> None:
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{what} must be finite numbers")


class PiecewiseLinearMap(_Strict):
    """A static map through the points (breakpoints[k], values[k]), extended linearly beyond the ends; in the channel's units (spec §11.2, §11.5.1)."""

    type: Literal["piecewise_linear"] = "piecewise_linear"
    breakpoints: list[float] = Field(min_length=2, description="Strictly increasing abscissae (input units).")
    values: list[float] = Field(min_length=2, description="The map's value at each breakpoint.")

    @model_validator(mode="after")
    def _check(self) -> "PiecewiseLinearMap":
        if len(self.values) != len(self.breakpoints):
            raise ValueError(f"{len(self.breakpoints)} breakpoints but {len(self.values)} values")
        _all_finite(self.breakpoints, "breakpoints")
        _all_finite(self.values, "values")
        if any(b <= a for a, b in zip(self.breakpoints, self.breakpoints[1:])):
            raise ValueError("breakpoints must be strictly increasing")
        return self


class UnitGainMap(_Strict):
    """No map: the channel passes unchanged (MATLAB: an empty or unitgain nonlinearity) (spec §11.2, §11.5.1)."""

    type: Literal["unit_gain"] = "unit_gain"


StaticMap = Annotated[Union[PiecewiseLinearMap, UnitGainMap], Field(discriminator="type")]


class TransferFunction(_Strict):
    """One linear block B_ji(q)/F_ji(q) with delay nk (spec §11.2)."""

    b: list[float] = Field(min_length=1, description="b_1 … b_nb of B(q) = b_1 + b_2 q^-1 + … (delay not included).")
    f: list[float] = Field(default_factory=list, description="f_1 … f_nf of F(q) = 1 + f_1 q^-1 + … (leading 1 not stored).")
    nk: int = Field(ge=0, description="Input delay in samples.")

    @model_validator(mode="after")
    def _check(self) -> "TransferFunction":
        _all_finite(self.b, "b")
        _all_finite(self.f, "f")
        return self


class Channel(_Strict):
    """One model input or output channel: its name and SI unit, in channel order (spec §11.1, §11.5.1)."""

    name: str
    unit: str


class QuaternionHemisphere(_Strict):
    """Sign convention of the quaternion inputs: each sample q is replaced by sign(q·reference)·q (spec §11.5.1)."""

    columns: list[int] = Field(min_length=4, max_length=4, description="0-based input indices of w, x, y, z.")
    reference: list[float] = Field(min_length=4, max_length=4, description="Unit quaternion [w, x, y, z].")


class FitSummary(_Strict):
    """How the model was obtained (informative; prediction never reads it); errors in output units (spec §11.5.1)."""

    session_id: str | None = None
    trial_id: str | None = None
    samples: int = Field(ge=0)
    iterations: int = Field(ge=0)
    stop_reason: str
    cost: float = Field(description="Final value of the normalised cost of spec §11.4.")
    rmse: list[float] = Field(description="Training RMS error per output, output units.")
    fit_percent: list[float] = Field(description="MATLAB's fit: 100 (1 - |y - yhat| / |y - mean y|) per output.")
    definition_version: str | None = Field(None, description="Version of metrics/dynamics.json used.")


class HWModelFile(_Strict):
    """A Hammerstein–Wiener model parameter file (spec §11.5; schema ``hw-model``)."""

    format: Literal["haptify-hw-model"] = MODEL_FORMAT
    spec_version: str = SPEC_VERSION
    sample_rate_hz: float = Field(gt=0, description="Rate the model runs at; inputs must be sampled at it.")
    inputs: list[Channel] = Field(min_length=1)
    outputs: list[Channel] = Field(min_length=1)
    input_maps: list[StaticMap] = Field(description="One map per input channel, in input order.")
    output_maps: list[StaticMap] = Field(description="One map per output channel, in output order.")
    linear: list[list[TransferFunction]] = Field(description="linear[j][i] = B_ji/F_ji from input i to output j (ny × nu).")
    quaternion_hemisphere: QuaternionHemisphere | None = None
    fit: FitSummary | None = None

    @model_validator(mode="after")
    def _shapes(self) -> "HWModelFile":
        nu, ny = len(self.inputs), len(self.outputs)
        if len(self.input_maps) != nu:
            raise ValueError(f"input_maps has {len(self.input_maps)} entries, inputs has {nu}")
        if len(self.output_maps) != ny:
            raise ValueError(f"output_maps has {len(self.output_maps)} entries, outputs has {ny}")
        if len(self.linear) != ny or any(len(row) != nu for row in self.linear):
            raise ValueError(f"linear must be {ny} rows of {nu} transfer functions")
        if self.quaternion_hemisphere is not None and any(not 0 <= c < nu for c in self.quaternion_hemisphere.columns):
            raise ValueError("quaternion_hemisphere.columns must be input indices")
        return self

    @property
    def nu(self) -> int:
        return len(self.inputs)

    @property
    def ny(self) -> int:
        return len(self.outputs)


def load_model(path: str | os.PathLike[str]) -> HWModelFile:
    """Read and validate a parameter file (spec §11.5); E702 names the field when it is invalid."""
    from haptify.formats.storage import read_json_model

    return read_json_model(path, HWModelFile, Code.HW_MODEL_INVALID)


def save_model(model: HWModelFile, path: str | os.PathLike[str]) -> Path:
    """Write the parameter file atomically (spec §3.6, §11.5)."""
    from haptify.formats.storage import atomic_write_text

    p = Path(path)
    atomic_write_text(p, model.model_dump_json(indent=2) + "\n")
    return p


def _cell(items: list[Any]) -> np.ndarray:
    out = np.empty((len(items),), dtype=object)
    for k, item in enumerate(items):
        out[k] = item
    return out


def _mat_map(m: PiecewiseLinearMap | UnitGainMap) -> dict[str, Any]:
    if isinstance(m, UnitGainMap):
        return {"Type": "unit_gain", "BreakPoints": np.zeros((2, 0))}
    return {"Type": "piecewise_linear", "BreakPoints": np.array([m.breakpoints, m.values], dtype=float)}


def model_to_mat_dict(model: HWModelFile) -> dict[str, Any]:
    """The MATLAB struct written by :func:`export_mat` (field names in spec §11.5.2)."""
    ny, nu = model.ny, model.nu
    B = np.empty((ny, nu), dtype=object)
    F = np.empty((ny, nu), dtype=object)
    nb = np.zeros((ny, nu))
    nf = np.zeros((ny, nu))
    nk = np.zeros((ny, nu))
    for j in range(ny):
        for i in range(nu):
            tf = model.linear[j][i]
            B[j, i] = np.concatenate([np.zeros(tf.nk), tf.b])[None, :]
            F[j, i] = np.concatenate([[1.0], tf.f])[None, :]
            nb[j, i], nf[j, i], nk[j, i] = len(tf.b), len(tf.f), tf.nk
    hemi = model.quaternion_hemisphere
    return {
        "Format": model.format,
        "SpecVersion": model.spec_version,
        "Ts": 1.0 / model.sample_rate_hz,
        "InputName": _cell([c.name for c in model.inputs]),
        "InputUnit": _cell([c.unit for c in model.inputs]),
        "OutputName": _cell([c.name for c in model.outputs]),
        "OutputUnit": _cell([c.unit for c in model.outputs]),
        "InputNonlinearity": _cell([_mat_map(m) for m in model.input_maps]),
        "OutputNonlinearity": _cell([_mat_map(m) for m in model.output_maps]),
        "B": B,
        "F": F,
        "nb": nb,
        "nf": nf,
        "nk": nk,
        "QuaternionColumns": (np.array(hemi.columns, dtype=float) + 1.0) if hemi else np.zeros(0),
        "QuaternionReference": np.array(hemi.reference, dtype=float) if hemi else np.zeros(0),
    }


def export_mat(model: HWModelFile, path: str | os.PathLike[str]) -> Path:
    """Write the model as a MATLAB-loadable ``.mat`` holding the struct ``model`` (spec §11.5.2)."""
    from scipy.io import savemat

    p = Path(path)
    payload = {"model": model_to_mat_dict(model)}
    from haptify.formats.storage import write_atomically

    write_atomically(p, lambda tmp: savemat(tmp, payload, do_compression=True, oned_as="row"))
    return p
