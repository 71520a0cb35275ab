"""The environment of a node container that replaces another on its host (pure).

A process started after its predecessor was killed can inherit what the predecessor left on the host: Fast DDS
gives it the same participant id, so the same ports, and its peers may still write into the dead one's shared
memory for seconds. A kind avoids that by rotating a replacement's profile file through a few that differ only
in their ports (:func:`rotate_profile`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import PurePosixPath


def rotate_profile(previous: Mapping[str, str], planned: Mapping[str, str], *, variables: Sequence[str],
                   rotation: Sequence[str]) -> dict[str, str]:
    """``planned``, where each of ``variables`` names a file called ``rotation[0]`` and the predecessor
    (``previous``) named ``rotation[i]`` in the same folder, pointed at ``rotation[i + 1]`` (after the last, back to
    the first): successive replacements go round the rotation, so a port comes back only every
    ``len(rotation)`` replacements. Anything else (another file, a variable the plan does not set) stays as planned."""
    env = dict(planned)
    for name in variables:
        path = env.get(name)
        if path is None or PurePosixPath(path).name != rotation[0]:
            continue
        before = previous.get(name)
        if before is None or PurePosixPath(before).parent != PurePosixPath(path).parent:
            continue
        was = PurePosixPath(before).name
        if was in rotation:
            env[name] = str(PurePosixPath(path).with_name(rotation[(rotation.index(was) + 1) % len(rotation)]))
    return env
