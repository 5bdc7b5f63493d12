"""MQTT topic templates: ``heliotwin/{site_id}/{array}/state`` and the like.

A template is a topic whose levels are either literal or one placeholder
(``{site_id}``, ``{array}``, ``{quantity}``, ``{sensor}``) filling the whole
level. :meth:`Template.match` reads the placeholders out of a received topic,
:meth:`Template.filter` gives the subscription filter (placeholders as ``+``,
some of them fixed), :meth:`Template.format` builds a topic to publish.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

_PLACEHOLDER = re.compile(r"^\{([a-z_]+)\}$")
#: Characters a placeholder value may not hold: level separator, wildcards, NUL.
_FORBIDDEN = re.compile(r"[/+#\x00]")


@dataclass(frozen=True)
class Template:
    """A topic template: its levels, and which of them are placeholders."""

    text: str
    levels: tuple[str, ...]
    names: tuple[str | None, ...]  # placeholder name per level, None for a literal level

    @classmethod
    def parse(cls, text: str, required: tuple[str, ...]) -> Template:
        """Check ``text`` (every name in ``required`` once, each a whole level) and parse it."""
        levels = tuple(text.split("/"))
        names = []
        for level in levels:
            m = _PLACEHOLDER.match(level)
            if m is None and ("{" in level or "}" in level):
                raise ValueError(f"topic template {text!r}: a placeholder must fill a whole "
                                 f"level, got {level!r}")
            if m is None and ("+" in level or "#" in level):
                raise ValueError(f"topic template {text!r}: no wildcards ({level!r})")
            names.append(m.group(1) if m else None)
        found = [n for n in names if n is not None]
        unknown = sorted(set(found) - set(required))
        if unknown or sorted(found) != sorted(required):
            raise ValueError(f"topic template {text!r} must hold each of "
                             f"{', '.join('{' + r + '}' for r in required)} once"
                             + (f"; unknown: {unknown}" if unknown else ""))
        return cls(text, levels, tuple(names))

    def match(self, topic: str) -> dict[str, str] | None:
        """The placeholder values of ``topic``, or None when it is not of this template."""
        parts = topic.split("/")
        if len(parts) != len(self.levels):
            return None
        out: dict[str, str] = {}
        for part, level, name in zip(parts, self.levels, self.names, strict=True):
            if name is None:
                if part != level:
                    return None
            else:
                out[name] = part
        return out

    def filter(self, **fixed: str) -> str:
        """The subscription filter: ``+`` for every placeholder not given in ``fixed``."""
        return "/".join(level if name is None else fixed.get(name, "+")
                        for level, name in zip(self.levels, self.names, strict=True))

    def format(self, **values: str) -> str:
        """The topic with every placeholder filled (each value a valid topic level)."""
        for key, value in values.items():
            if not value or _FORBIDDEN.search(value):
                raise ValueError(f"{key} {value!r} cannot be an MQTT topic level")
        return "/".join(level if name is None else values[name]
                        for level, name in zip(self.levels, self.names, strict=True))


@dataclass(frozen=True)
class Topics:
    """The service's templates, from ``Settings.mqtt_*_topic``."""

    state: Template
    value: Template
    errors: Template
    ha_state: Template
    ha_prefix: str

    @classmethod
    def from_settings(cls, state: str, value: str, errors: str, ha_state: str,
                      ha_prefix: str) -> Topics:
        """Parse and check the templates (ValueError naming the setting on a bad one)."""
        out = []
        for setting, text, required in (
            ("mqtt_state_topic", state, ("site_id", "array")),
            ("mqtt_value_topic", value, ("site_id", "array", "quantity")),
            ("mqtt_errors_topic", errors, ("site_id",)),
            ("mqtt_ha_state_topic", ha_state, ("site_id", "array", "sensor")),
        ):
            try:
                out.append(Template.parse(text, required))
            except ValueError as exc:
                raise ValueError(f"HELIOTWIN_{setting.upper()}: {exc}") from None
        if not ha_prefix or _FORBIDDEN.search(ha_prefix.strip("/").replace("/", "")):
            raise ValueError(f"HELIOTWIN_MQTT_HA_PREFIX: {ha_prefix!r} is not a topic prefix")
        return cls(out[0], out[1], out[2], out[3], ha_prefix.strip("/"))
