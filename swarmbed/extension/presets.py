"""Named presets of a plugin's parameters: the switches that exist to follow one paper's text or one
code base, grouped under one name, so that an experiment says ``allocator: {name: fcg, preset:
space_text}`` instead of flipping each key.

A plugin declares its presets on its ``Params`` model as ``presets: ClassVar[dict[str, Preset]]``.
A preset only fills keys: a key the experiment sets itself wins over the preset's value, and a run
folder's ``config.yaml`` holds every resolved value (the preset's name is not kept: the values are
what ran). ``swarmbed params NAME`` lists each preset and what it sets.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

#: the key of a scenario or allocator section that names a preset
PRESET_KEY = "preset"


@dataclass(frozen=True)
class Preset:
    """Values of a plugin's parameters that follow one text or one code base, and which (``source``:
    the sentence, section or file it follows)."""

    values: Mapping[str, Any]
    source: str


class PresetError(ValueError):
    """A preset name a plugin does not declare; the message lists those it does."""


def presets_of(params_model: type) -> dict[str, Preset]:
    """The presets a ``Params`` model declares (none: an empty map)."""
    found = getattr(params_model, "presets", None)
    return dict(found) if isinstance(found, Mapping) else {}


def apply_preset(params_model: type, params: Mapping[str, Any], section: str) -> dict[str, Any]:
    """``params`` with the preset it names (under :data:`PRESET_KEY`) filled in below its own keys."""
    given = dict(params)
    if PRESET_KEY not in given:
        return given
    name = given.pop(PRESET_KEY)
    if name is None:  # ``preset: null``: none
        return given
    known = presets_of(params_model)
    if not isinstance(name, str) or name not in known:
        offered = ", ".join(sorted(known)) or "none"
        raise PresetError(f"{section}.{PRESET_KEY}: {name!r} is not one of this plugin's presets ({offered})")
    return {**known[name].values, **given}
