"""A component's CPU and memory in robot.yaml: what it is guaranteed, what it may use at most, and whether the
robot can lose it.

```yaml
resources:
  requests: {cpu: 0.5, memory: 256Mi}   # guaranteed: CPU shares / reservation, the pod's requests
  limits: {cpu: 2, memory: 1Gi}         # at most: the container is throttled past cpu, killed past memory
  priority: critical                    # killed last when the host runs out of memory (default: normal)
```

CPU is in cores (``0.5``, ``2``) or millicores (``"500m"``); memory in bytes or with a binary or decimal suffix
(``256Mi``, ``1Gi``, ``512M``), as Kubernetes writes them. The same values reach ``run`` (Docker's ``--cpus``,
``--memory``, ``--cpu-shares``, ``--memory-reservation``, ``--oom-score-adj``), the Swarm services (limits and
reservations) and the pods (``resources`` of the container). Each is held as an integer: millicores and bytes.
"""

from __future__ import annotations

import re
from typing import Annotated, Literal

from pydantic import BeforeValidator, Field, WithJsonSchema

from robocore.config.strict import Strict
from robocore.config.values import shown

_CPU = re.compile(r"^(?P<n>[0-9]+(?:\.[0-9]+)?)(?P<m>m?)$")
_MEMORY = re.compile(r"^(?P<n>[0-9]+)(?P<unit>Ki|Mi|Gi|Ti|k|K|M|G|T)?$")
_UNITS = {None: 1, "k": 1000, "K": 1000, "M": 1000**2, "G": 1000**3, "T": 1000**4,
          "Ki": 1024, "Mi": 1024**2, "Gi": 1024**3, "Ti": 1024**4}
#: A host has far fewer; a bigger figure is a typo.
MAX_CPU_MILLIS = 1024 * 1000
MIN_MEMORY, MAX_MEMORY = 6 * 1024**2, 16 * 1024**4


def _millicores(value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ValueError(f"must be a number of cores (0.5, 2) or of millicores ('500m'), got {shown(value)}")
    match = _CPU.match(str(value).strip())
    if match is None:
        raise ValueError(f"must be a number of cores (0.5, 2) or of millicores ('500m'), got {shown(value)}")
    number = float(match["n"])
    millis = round(number if match["m"] else number * 1000)
    if not 1 <= millis <= MAX_CPU_MILLIS:
        raise ValueError(f"must be between 0.001 and {MAX_CPU_MILLIS // 1000} cores, got {shown(value)}")
    return millis


def _bytes(value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, str)):
        raise ValueError(f"must be bytes or a size such as 256Mi, 1Gi or 512M, got {shown(value)}")
    match = _MEMORY.match(str(value).strip())
    if match is None:
        raise ValueError(f"must be bytes or a size such as 256Mi, 1Gi or 512M, got {shown(value)}")
    size = int(match["n"]) * _UNITS[match["unit"]]
    if not MIN_MEMORY <= size <= MAX_MEMORY:  # Docker refuses a memory limit below 6 MiB
        raise ValueError(f"must be between 6Mi and 16Ti, got {shown(value)}")
    return size


def integers(low: int, high: int) -> str:
    """A regular expression (no anchors) of the decimal integers from ``low`` to ``high`` (``low`` >= 1), leading
    zeros allowed: the schema's strings then accept exactly the sizes the model takes, as an editor should."""
    parts: list[str] = []

    def span(lo: int, hi: int) -> None:
        low_text, high_text = str(lo), str(hi)
        if len(low_text) < len(high_text):
            span(lo, 10 ** len(low_text) - 1)
            span(10 ** len(low_text), hi)
            return
        if lo == hi:
            parts.append(low_text)
            return
        at = next(i for i, (a, b) in enumerate(zip(low_text, high_text, strict=True)) if a != b)
        prefix, rest = low_text[:at], len(low_text) - at - 1
        tail = f"[0-9]{{{rest}}}" if rest else ""
        first, last = int(low_text[at]), int(high_text[at])
        if low_text[at + 1:] != "0" * rest:
            span(lo, int(f"{prefix}{first}{'9' * rest}"))
            first += 1
        ends_at_nines = high_text[at + 1:] == "9" * rest
        if first <= (last if ends_at_nines else last - 1):
            parts.append(f"{prefix}[{first}-{last if ends_at_nines else last - 1}]{tail}")
        if not ends_at_nines:
            span(int(f"{prefix}{last}{'0' * rest}"), hi)

    span(low, high)
    return "0*(?:" + "|".join(parts) + ")"


_MEMORY_TEXT = "^(?:" + "|".join(
    integers(-(-MIN_MEMORY // factor), MAX_MEMORY // factor) + (unit or "")
    for unit, factor in _UNITS.items()) + ")$"
_CPU_TEXT = (f"^(?:{integers(1, MAX_CPU_MILLIS // 1000)}|{integers(1, MAX_CPU_MILLIS // 1000 - 1)}\\.[0-9]+"
             f"|0*0\\.(?:[1-9]|[0-9][1-9]|[0-9][0-9][1-9])[0-9]*|{integers(1, MAX_CPU_MILLIS)}m)$")

Millicores = Annotated[int, BeforeValidator(_millicores), WithJsonSchema(
    {"anyOf": [{"type": "number", "minimum": 0.001, "maximum": MAX_CPU_MILLIS // 1000},
               {"type": "string", "pattern": _CPU_TEXT}],
     "description": "Cores (0.5, 2) or millicores ('500m'), from 0.001 to 1024 cores."})]
Bytes = Annotated[int, BeforeValidator(_bytes), WithJsonSchema(
    {"anyOf": [{"type": "integer", "minimum": MIN_MEMORY, "maximum": MAX_MEMORY},
               {"type": "string", "pattern": _MEMORY_TEXT}],
     "description": "Bytes, or a size with Ki, Mi, Gi, Ti (binary) or k, M, G, T (decimal), from 6Mi to 16Ti."})]


class Amounts(Strict):
    """CPU and memory of one kind (requests or limits); each optional."""

    cpu: Millicores | None = None
    memory: Bytes | None = None


class Resources(Strict):
    """What a component is guaranteed (requests), may use at most (limits), and whether the robot can lose it."""

    requests: Amounts = Field(default_factory=Amounts, description="Guaranteed: CPU shares and a memory reservation "
                              "under Docker, the pod's requests on Kubernetes.")
    limits: Amounts = Field(default_factory=Amounts, description="At most: the container is throttled past cpu and "
                            "killed past memory.")
    priority: Literal["normal", "critical"] = Field(default="normal", description="critical: the component is killed "
                                                    "last when its host runs out of memory.")



def over_limits(resources: Resources) -> list[str]:
    """A request above its limit, in words (a cross-field rule: ``validate`` reports it, the schema cannot)."""
    return [f"requests.{key} is more than limits.{key}: ask for at most what the limit allows"
            for key in ("cpu", "memory")
            if (asked := getattr(resources.requests, key)) is not None
            and (most := getattr(resources.limits, key)) is not None and asked > most]
