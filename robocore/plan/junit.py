"""JUnit XML test results: reading the files colcon's test runs leave, and one merged file per package (pure).

pytest (``--junit-xml``, which colcon passes for ``ament_python`` packages), gtest and
ament_cmake's test runners all write JUnit XML: a ``<testsuite>``, or ``<testsuites>`` holding
several, with one ``<testcase classname=... name=...>`` per test that holds a ``<failure>``,
``<error>`` or ``<skipped>`` element when the test did not pass. Counts are taken from the
test cases themselves, not from the suites' summary attributes. A file that is not JUnit XML
is reported as a problem of its package, never skipped in silence: the package then has an
error, because nobody can tell whether its tests passed.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field

from robocore.errors import RobocoreError

#: Lines of a failure message shown per failing test.
MESSAGE_LINES = 3
#: Characters kept of each message line.
LINE_WIDTH = 200
ROOT_TAGS = ("testsuite", "testsuites")


class MalformedResults(RobocoreError):
    """A test result file that is not JUnit XML."""


@dataclass(frozen=True)
class Case:
    """One test and how it ended: ``passed``, ``failed``, ``error`` or ``skipped``."""

    classname: str
    name: str
    outcome: str
    message: str = ""

    @property
    def test_id(self) -> str:
        """``classname::name``, the name a failing test is reported by."""
        return f"{self.classname}::{self.name}" if self.classname else self.name


@dataclass(frozen=True)
class PackageResults:
    """The test cases of one package, and the result files of it that could not be read."""

    package: str
    cases: tuple[Case, ...] = ()
    problems: tuple[str, ...] = field(default=())

    @property
    def tests(self) -> int:
        """Test cases found (skipped ones included)."""
        return len(self.cases)

    @property
    def failures(self) -> int:
        """Tests that failed an assertion."""
        return sum(1 for c in self.cases if c.outcome == "failed")

    @property
    def errors(self) -> int:
        """Tests that errored, plus one per unreadable result file."""
        return sum(1 for c in self.cases if c.outcome == "error") + len(self.problems)

    @property
    def skipped(self) -> int:
        """Tests skipped (or expected to fail)."""
        return sum(1 for c in self.cases if c.outcome == "skipped")

    @property
    def ok(self) -> bool:
        """No failure and no error."""
        return self.failures == 0 and self.errors == 0

    @property
    def not_passed(self) -> list[Case]:
        """The failed and errored tests, in file order."""
        return [c for c in self.cases if c.outcome in ("failed", "error")]


def _root(data: bytes, source: str) -> ET.Element:
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        raise MalformedResults(f"{source}: not readable as XML ({exc})") from None
    if root.tag not in ROOT_TAGS:
        raise MalformedResults(f"{source}: not JUnit XML (root element <{root.tag}>, "
                               "expected <testsuite> or <testsuites>)")
    return root


def first_lines(text: str, lines: int = MESSAGE_LINES) -> str:
    """The first ``lines`` non-blank lines of ``text``, each cut to :data:`LINE_WIDTH` characters."""
    kept = [line.rstrip()[:LINE_WIDTH] for line in text.splitlines() if line.strip()]
    return "\n".join(kept[:lines])


def _case(element: ET.Element) -> Case:
    outcome, message = "passed", ""
    for tag, name in (("error", "error"), ("failure", "failed"), ("skipped", "skipped")):
        found = element.find(tag)
        if found is not None:
            outcome = name
            message = first_lines(found.get("message") or found.text or "")
            break
    else:
        if element.get("status") == "notrun":  # gtest: a DISABLED_ test
            outcome = "skipped"
    return Case(classname=element.get("classname", ""), name=element.get("name", ""), outcome=outcome,
                message=message)


def read_cases(data: bytes, source: str) -> list[Case]:
    """The test cases of one JUnit XML document; ``source`` names it in a MalformedResults."""
    return [_case(element) for element in _root(data, source).iter("testcase")]


def package_results(package: str, files: Sequence[tuple[str, bytes]]) -> PackageResults:
    """Every test case of a package's result files ``(name, contents)``; unreadable files become problems."""
    cases: list[Case] = []
    problems: list[str] = []
    for source, data in files:
        try:
            cases += read_cases(data, source)
        except MalformedResults as exc:
            problems.append(exc.message)
    return PackageResults(package=package, cases=tuple(cases), problems=tuple(problems))


def merged(results: PackageResults, files: Sequence[tuple[str, bytes]]) -> bytes:
    """One JUnit document for a package: ``<testsuites name=package>`` with the suites of every readable
    file, plus a suite with one errored test per unreadable file (so CI reports it too)."""
    root = ET.Element("testsuites", {
        "name": results.package, "tests": str(results.tests + len(results.problems)),
        "failures": str(results.failures), "errors": str(results.errors), "skipped": str(results.skipped),
    })
    for source, data in files:
        try:
            document = _root(data, source)
        except MalformedResults:
            continue
        root.extend([document] if document.tag == "testsuite" else [s for s in document if s.tag == "testsuite"])
    if results.problems:
        count = str(len(results.problems))
        suite = ET.SubElement(root, "testsuite", {"name": f"{results.package}.results", "tests": count,
                                                  "failures": "0", "errors": count, "skipped": "0"})
        for index, problem in enumerate(results.problems):
            case = ET.SubElement(suite, "testcase", {"classname": f"{results.package}.results",
                                                     "name": f"unreadable_result_{index}"})
            ET.SubElement(case, "error", {"message": problem})
    text: bytes = ET.tostring(root, encoding="utf-8", xml_declaration=True)
    return text + b"\n"
