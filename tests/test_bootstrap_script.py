"""scripts/bootstrap.sh bootstraps the Debian root image ahead exactly as prepare-base would make it."""

from __future__ import annotations

import re
from pathlib import Path

from robocore.adapters import rootfs

SCRIPT = (Path(__file__).resolve().parents[1] / "scripts" / "bootstrap.sh").read_text()


def test_the_root_image_made_ahead_is_the_one_prepare_base_makes() -> None:
    assert f"--include={rootfs.INCLUDE} bookworm" in SCRIPT
    assert "--variant=apt" in SCRIPT
    assert re.search(rf"docker import \S+ {re.escape(rootfs.BOOTSTRAPPED)}", SCRIPT)
    assert f"${{{rootfs.MIRROR_ENV}:-{rootfs.DEFAULT_MIRROR}}}" in SCRIPT
    for ref in (rootfs.BOOTSTRAPPED, rootfs.UPSTREAM):  # an image prepare-base would take is never replaced
        assert f"docker image inspect {ref} >/dev/null 2>&1 && return 0" in SCRIPT


def test_the_demo_asks_for_it_and_the_tests_do_not() -> None:
    demo = (Path(__file__).resolve().parents[1] / "scripts" / "demo").read_text()
    test = (Path(__file__).resolve().parents[1] / "scripts" / "test").read_text()
    assert "export ROBOCORE_PREFETCH_ROOT=1" in demo
    assert "ROBOCORE_PREFETCH_ROOT" not in test
