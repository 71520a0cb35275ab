"""Image builds through a fake daemon: how a failed build is reported."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from robocore.adapters.image_builder import build_image
from robocore.errors import BuildError
from robocore.plan.dockerfiles import ImagePlan


class _Api:
    def __init__(self, chunks: list[dict[str, Any]]) -> None:
        self.chunks = chunks

    def build(self, **_: Any) -> Iterator[dict[str, Any]]:
        return iter(self.chunks)


class _Client:
    def __init__(self, chunks: list[dict[str, Any]]) -> None:
        self.api = _Api(chunks)


PLAN = ImagePlan(role="component", name="proj-talker", tag="latest", arch="amd64",
                 dockerfile="FROM proj-base:latest\n", parent="proj-base:latest")
ROSDEP_FAILED = [
    {"stream": "Step 3/5 : RUN apt-get update && /robocore/entrypoint.sh rosdep install ...\n"},
    {"stream": "ERROR: the following packages/stacks could not have their rosdep keys resolved\n"},
    {"stream": "to system dependencies:\n"},
    {"stream": "demo_talker: Cannot locate rosdep definition for [no_such_key]\n"},
    {"error": "The command '/bin/bash -o pipefail -c apt-get update && ...' returned a non-zero code: 1"},
]


def test_a_key_rosdep_cannot_resolve_is_one_line_naming_package_and_key() -> None:
    with pytest.raises(BuildError) as failed:
        build_image(_Client(ROSDEP_FAILED), PLAN, [], labels={}, native_arch="amd64")  # type: ignore[arg-type]
    assert failed.value.message == ("image proj-talker:latest: rosdep cannot install the dependencies: "
                                    "package demo_talker: no rosdep definition of 'no_such_key'")
    assert "\n" not in failed.value.message
    assert failed.value.hint is not None and "apt_packages" in failed.value.hint


def test_another_failure_keeps_the_end_of_the_build_output() -> None:
    chunks = [{"stream": "Step 2/2 : RUN make\n"}, {"stream": "make: *** [all] Error 2\n"},
              {"error": "The command '/bin/sh -c make' returned a non-zero code: 2"}]
    with pytest.raises(BuildError) as failed:
        build_image(_Client(chunks), PLAN, [], labels={}, native_arch="amd64")  # type: ignore[arg-type]
    assert "returned a non-zero code: 2" in failed.value.message
    assert "make: *** [all] Error 2" in failed.value.message
