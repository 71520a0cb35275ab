"""The environment of a node container that replaces another on its host (pure).

A process started after its predecessor was killed can inherit what the predecessor left on the host: Fast DDS
gives it the same participant id, so the same ports, and its peers may still write into the dead one's shared
memory for seconds. A kind avoids that by alternating a replacement's profile file between two that differ only
in their ports (:func:`alternate_profile`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import PurePosixPath


def alternate_profile(previous: Mapping[str, str], planned: Mapping[str, str], *, variables: Sequence[str],
                      primary: str, alternate: str) -> dict[str, str]:
    """``planned``, where each of ``variables`` names a file called ``primary`` that the predecessor
    (``previous``) named too, pointed at ``alternate`` in the same folder; so successive replacements alternate
    between the two. Anything else (another file, a variable the plan does not set) stays as planned."""
    env = dict(planned)
    for name in variables:
        path = env.get(name)
        if path is None or PurePosixPath(path).name != primary:
            continue
        if previous.get(name) == path:
            env[name] = str(PurePosixPath(path).with_name(alternate))
    return env
