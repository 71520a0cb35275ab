"""Files robocore bakes into images: entrypoint, the wheels and debian setup.bash files, the ``ros2`` shim."""

from __future__ import annotations

from importlib import resources


def read(name: str) -> bytes:
    """The bytes of resource file ``name``."""
    return resources.files(__name__).joinpath(name).read_bytes()
