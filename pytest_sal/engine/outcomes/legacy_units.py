"""Outcomes stored before every value was in its parameter's declared unit.

Up to runner version 1, three parameters were searched, bounded and recorded in a search unit
of their own: ``night.illuminance_lux`` in log10 lx, ``sensor_noise.iso`` in stops above
ISO 100 and ``frame_drop.drop_rate`` in percent. History written then is converted on reading,
so a comparison never sets 0.7 "log10 lx" against 5 lx. Anything else whose unit disagrees with
the parameter's unit today is refused by the regression checks, with a message.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

__all__ = ["LEGACY_UNITS", "upgrade_outcome"]

#: old unit (and the parameter name it belonged to) -> (conversion to the declared unit, unit)
LEGACY_UNITS: dict[tuple[str, str], tuple[Callable[[float], float], str]] = {
    ("illuminance_lux", "log10 lx"): (lambda decade: 10.0**decade, "lx"),
    ("iso", "stops above ISO 100"): (lambda stops: 100.0 * 2.0**stops, "ISO"),
    ("drop_rate", "%"): (lambda percent: percent / 100.0, ""),
}


def upgrade_outcome(data: dict[str, Any]) -> dict[str, Any]:
    """``data`` (an ``Outcome.to_dict``) with values in a legacy search unit converted to the
    parameter's declared unit; other outcomes are returned as they are."""
    boundary = data.get("boundary") or {}
    name = str(data.get("parameter", "")).rsplit(".", 1)[-1]
    rule = LEGACY_UNITS.get((name, str(boundary.get("unit", ""))))
    if rule is None:
        return data
    convert, unit = rule

    def value(v: Any) -> Any:
        return None if v is None else convert(float(v))

    old_envelope = str(data.get("envelope", ""))
    data = dict(data)
    data["boundary"] = dict(boundary, pass_value=value(boundary.get("pass_value")), fail_value=value(boundary.get("fail_value")), unit=unit)
    if data.get("previous"):
        previous = data["previous"]
        data["previous"] = dict(
            previous, pass_value=value(previous.get("pass_value")), fail_value=value(previous.get("fail_value")), unit=unit
        )
    data["edge"] = value(data.get("edge"))
    data["trials"] = [dict(t, value=convert(float(t["value"]))) for t in data.get("trials", [])]
    pass_value, edge = data["boundary"]["pass_value"], data["edge"]
    if pass_value is not None and edge is not None:
        data["margin"] = (edge - pass_value) if data.get("worse") == "lower" else (pass_value - edge)
    match = re.fullmatch(r"(>=|>|<=|<) (\S+) .*", old_envelope)
    if match and edge is not None:
        data["envelope"] = f"{match.group(1)} {edge:g}{' ' + unit if unit else ''}"
        data["requirement"] = str(data.get("requirement", "")).replace(old_envelope, data["envelope"])
    return data
