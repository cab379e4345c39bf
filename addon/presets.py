"""Presets: TOML data files in presets/, validated against the catalog (addon/catalog.py).

A preset file names a model by its catalog id and gives parameter values by catalog parameter
id; everything it leaves out takes the catalog default. The file's stem is the preset id.

    format = 1
    model = "walter_reflection"            # catalog model id
    label = "Gold"                         # shown in the UI
    description = "Polished gold, ..."
    [source]                               # required: where the values come from
    citation = "P. B. Johnson and R. W. Christy, Phys. Rev. B 6, 4370 (1972)"
    url = "https://refractiveindex.info/?shelf=main&book=Au&page=Johnson"
    wavelengths_nm = [650, 550, 450]       # required when the preset sets n or k (R, G, B)
    [params]
    roughness = 0.2
    fresnel_type = "conductor"
    n = [0.156, 0.424, 1.38]
    k = [3.602, 2.472, 1.914]

Validation never clamps: an unknown model, an unknown key or parameter, a wrong type, a value
outside the catalog's range or an unknown enum item is a PresetError naming the file and the
field. Files are parsed with the standard library's tomllib; nothing in them is executed.
No bpy here.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from .catalog import COLOR, ENUM, FLOAT, MODELS, Model

PRESETS_DIR = Path(__file__).resolve().parent.parent / "presets"
FORMAT = 1
TOP_KEYS = {"format", "model", "label", "description", "category", "source", "params"}
REQUIRED = ("model", "label", "description", "source", "params")
SOURCE_KEYS = {"citation", "url", "wavelengths_nm", "method", "note"}
# Parameters whose values are measured optical constants: a preset that sets one must cite it.
OPTICAL = {"ior", "n", "k"}


class PresetError(ValueError):
    """A malformed preset. `path` is the file, `field` the offending field (dotted)."""

    def __init__(self, path, field_name: str, message: str):
        self.path = Path(path)
        self.field = field_name
        self.message = message
        super().__init__(f"{self.path.name}: {field_name}: {message}")


@dataclass(frozen=True)
class Preset:
    id: str
    path: Path
    model_id: str
    label: str
    description: str
    category: str
    source: dict
    params: dict = field(default_factory=dict)  # as given in the file (colours as tuples)

    @property
    def model(self) -> Model:
        return MODELS[self.model_id]

    def resolved(self) -> dict:
        """Every parameter of the model: catalog defaults overlaid with the preset's values
        (already validated, so the catalog's clamp changes nothing)."""
        return self.model.resolve(self.params)

    def citation(self) -> str:
        return self.source.get("citation", "")


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_number(path, name, v, param) -> float:
    if not _is_number(v):
        raise PresetError(path, name, f"expected a number for {param.label}, got {type(v).__name__} {v!r}")
    v = float(v)
    if not math.isfinite(v):
        raise PresetError(path, name, f"{v!r} is not finite")
    if (param.min is not None and v < param.min) or (param.max is not None and v > param.max):
        raise PresetError(path, name, f"{v!r} is out of range [{param.min:g}, {param.max:g}] "
                                      f"for {param.label} (the catalog's range; presets are never clamped)")
    return v


def validate_value(path, param, value, name: str | None = None):
    """The value as the catalog expects it, or a PresetError. Never clamps."""
    name = name or f"params.{param.id}"
    if param.kind == ENUM:
        if not isinstance(value, str):
            raise PresetError(path, name, f"expected one of {list(param.items)} (a string), "
                                          f"got {type(value).__name__} {value!r}")
        if value not in param.items:
            raise PresetError(path, name, f"unknown item {value!r}; {param.label} accepts {list(param.items)}")
        return value
    if param.kind == COLOR:
        if not isinstance(value, list) or len(value) != 3:
            raise PresetError(path, name, f"expected a list of 3 numbers (R, G, B) for {param.label}, got {value!r}")
        return tuple(_check_number(path, f"{name}[{i}]", v, param) for i, v in enumerate(value))
    assert param.kind == FLOAT, param.kind
    return _check_number(path, name, value, param)


def parse_preset(data: dict, path) -> Preset:
    """Validate a parsed TOML table (see the module docstring) and return the Preset."""
    path = Path(path)
    unknown = sorted(set(data) - TOP_KEYS)
    if unknown:
        raise PresetError(path, unknown[0], f"unknown key; accepted: {sorted(TOP_KEYS)}")
    for key in REQUIRED:
        if key not in data:
            raise PresetError(path, key, "missing")
    fmt = data.get("format", FORMAT)
    if fmt != FORMAT:
        raise PresetError(path, "format", f"unsupported format {fmt!r} (this add-on reads {FORMAT})")
    for key in ("model", "label", "description", "category"):
        if key in data and (not isinstance(data[key], str) or not data[key].strip()):
            raise PresetError(path, key, f"expected a non-empty string, got {data[key]!r}")
    model_id = data["model"]
    if model_id not in MODELS:
        raise PresetError(path, "model", f"unknown model {model_id!r}; this add-on has {sorted(MODELS)}")
    model = MODELS[model_id]

    source = data["source"]
    if not isinstance(source, dict):
        raise PresetError(path, "source", "expected a table [source] with a citation")
    for key in sorted(set(source) - SOURCE_KEYS):
        raise PresetError(path, f"source.{key}", f"unknown key; accepted: {sorted(SOURCE_KEYS)}")
    citation = source.get("citation")
    if not isinstance(citation, str) or not citation.strip():
        raise PresetError(path, "source.citation", "missing: every preset cites the source of its values")

    params = data["params"]
    if not isinstance(params, dict):
        raise PresetError(path, "params", "expected a table [params] of catalog parameter ids")
    values = {}
    accepted = [p.id for p in model.params]
    for pid, value in params.items():
        if pid not in accepted:
            raise PresetError(path, f"params.{pid}", f"unknown parameter of {model_id}; accepted: {accepted}")
        values[pid] = validate_value(path, model.param(pid), value)
    if {"n", "k"} & set(values):
        wl = source.get("wavelengths_nm")
        if not (isinstance(wl, list) and len(wl) == 3 and all(_is_number(w) and 300 <= w <= 800 for w in wl)):
            raise PresetError(path, "source.wavelengths_nm",
                              "a preset that sets n or k states the wavelengths of R, G, B in nm "
                              f"(3 numbers in [300, 800]), got {wl!r}")
    return Preset(id=path.stem, path=path, model_id=model_id, label=data["label"].strip(),
                  description=data["description"].strip(), category=data.get("category", "other"),
                  source=dict(source), params=values)


def load_preset(path) -> Preset:
    path = Path(path)
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as error:
        raise PresetError(path, "(toml syntax)", str(error)) from None
    except OSError as error:
        raise PresetError(path, "(file)", str(error)) from None
    return parse_preset(data, path)


def scan(directory=PRESETS_DIR) -> tuple[dict[str, Preset], list[PresetError]]:
    """Every preset of `directory` (sorted by id) and the errors of the malformed ones, so that
    one bad file does not hide the others."""
    presets, errors = {}, []
    for path in sorted(Path(directory).glob("*.toml")):
        try:
            presets[path.stem] = load_preset(path)
        except PresetError as error:
            errors.append(error)
    return presets, errors


def load_all(directory=PRESETS_DIR) -> dict[str, Preset]:
    """Every preset of `directory`; the first malformed file raises its PresetError."""
    presets, errors = scan(directory)
    if errors:
        raise errors[0]
    return presets


def find(preset_id: str, directory=PRESETS_DIR) -> Preset:
    """Load one preset by id (re-read from disk, so an edit is seen)."""
    path = Path(directory) / f"{preset_id}.toml"
    if not path.is_file():
        known = sorted(p.stem for p in Path(directory).glob("*.toml"))
        raise PresetError(path, "(file)", f"no preset {preset_id!r}; known: {known}")
    return load_preset(path)

