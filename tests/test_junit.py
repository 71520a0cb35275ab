"""Reading JUnit XML results (robocore.plan.junit): pytest's real output, gtest's, and files that are not JUnit."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from robocore.plan import junit

PASSING = b"""<?xml version="1.0" encoding="utf-8"?>
<testsuites><testsuite name="pytest" errors="0" failures="0" skipped="0" tests="2">
<testcase classname="demo_talker.test.test_greeting" name="test_one" time="0.001" />
<testcase classname="demo_talker.test.test_greeting" name="test_two" time="0.001" />
</testsuite></testsuites>
"""

FAILING = b"""<?xml version="1.0" encoding="utf-8"?>
<testsuite name="pytest" errors="0" failures="1" skipped="0" tests="2">
<testcase classname="pkg.test.test_a" name="test_ok" />
<testcase classname="pkg.test.test_a" name="test_wrong">
<failure message="AssertionError: assert 'a' == 'b'&#10;  &#10;  - b&#10;  + a&#10;  more">
test/test_a.py:3: in test_wrong
    assert "a" == "b"
E   AssertionError</failure>
</testcase>
</testsuite>
"""


def test_a_passing_run() -> None:
    cases = junit.read_cases(PASSING, "pytest.xml")
    assert [(c.test_id, c.outcome) for c in cases] == [
        ("demo_talker.test.test_greeting::test_one", "passed"),
        ("demo_talker.test.test_greeting::test_two", "passed"),
    ]
    results = junit.package_results("demo_talker", [("pytest.xml", PASSING)])
    assert (results.tests, results.failures, results.errors, results.skipped, results.ok) == (2, 0, 0, 0, True)
    assert results.not_passed == []


def test_a_failure_is_named_with_the_first_lines_of_its_message() -> None:
    results = junit.package_results("pkg", [("pytest.xml", FAILING)])
    assert (results.tests, results.failures, results.errors, results.ok) == (2, 1, 0, False)
    [case] = results.not_passed
    assert case.test_id == "pkg.test.test_a::test_wrong"
    assert case.outcome == "failed"
    # blank lines dropped, three lines kept: the fourth ("+ a") and later are not
    assert case.message == "AssertionError: assert 'a' == 'b'\n  - b\n  + a"


def test_errors_skips_and_the_text_when_there_is_no_message_attribute() -> None:
    data = b"""<testsuites><testsuite name="s">
      <testcase classname="c" name="broken"><error>fixture 'x' not found
      second line</error></testcase>
      <testcase classname="c" name="later"><skipped message="not on amd64"/></testcase>
      <testcase classname="c" name="expected" ><skipped type="pytest.xfail" message="known bug"/></testcase>
    </testsuite></testsuites>"""
    results = junit.package_results("p", [("r.xml", data)])
    assert [(c.name, c.outcome) for c in results.cases] == [
        ("broken", "error"), ("later", "skipped"), ("expected", "skipped")]
    assert results.cases[0].message == "fixture 'x' not found\n      second line"
    assert (results.failures, results.errors, results.skipped, results.ok) == (0, 1, 2, False)


def test_counts_come_from_the_test_cases_not_from_the_suite_summary() -> None:
    lying = b"""<testsuite name="s" tests="99" failures="0" errors="0">
      <testcase classname="c" name="t"><failure message="boom"/></testcase></testsuite>"""
    results = junit.package_results("p", [("r.xml", lying)])
    assert (results.tests, results.failures, results.ok) == (1, 1, False)


def test_gtest_disabled_tests_are_skipped_and_nested_suites_are_read() -> None:
    gtest = b"""<testsuites tests="3" name="AllTests">
      <testsuite name="Math" tests="3">
        <testcase name="adds" status="run" result="completed" classname="Math"/>
        <testcase name="DISABLED_divides" status="notrun" result="suppressed" classname="Math"/>
        <testcase name="subtracts" status="run" result="completed" classname="Math">
          <failure message="Expected equality of these values:&#10;  1&#10;  2" type=""/>
        </testcase>
      </testsuite></testsuites>"""
    results = junit.package_results("math", [("test_results/math/math.gtest.xml", gtest)])
    assert [(c.test_id, c.outcome) for c in results.cases] == [
        ("Math::adds", "passed"), ("Math::DISABLED_divides", "skipped"), ("Math::subtracts", "failed")]
    assert results.not_passed[0].message == "Expected equality of these values:\n  1\n  2"


@pytest.mark.parametrize(("data", "expected"), [
    (b"<testsuite><testcase name='x'></testsuite>", "r.xml: not readable as XML (mismatched tag: line 1, column"),
    (b"", "r.xml: not readable as XML (no element found: line 1, column 0)"),
    (b"<coverage version='7'/>", "r.xml: not JUnit XML (root element <coverage>, expected <testsuite> or"),
])
def test_a_file_that_is_not_junit_is_one_line_and_an_error_of_its_package(data: bytes, expected: str) -> None:
    with pytest.raises(junit.MalformedResults) as caught:
        junit.read_cases(data, "r.xml")
    assert caught.value.message.startswith(expected)
    assert "\n" not in caught.value.message
    results = junit.package_results("p", [("ok.xml", PASSING), ("r.xml", data)])
    assert results.tests == 2  # the readable file still counts
    assert results.problems == (caught.value.message,)
    assert (results.errors, results.ok) == (1, False)


def test_no_result_file_means_no_tests_and_no_failure() -> None:
    results = junit.package_results("p", [])
    assert (results.tests, results.ok) == (0, True)


def test_first_lines_cuts_long_lines() -> None:
    assert junit.first_lines("x" * 500 + "\n\n\ny\nz\nw") == "x" * junit.LINE_WIDTH + "\ny\nz"


def test_merged_file_keeps_every_suite_and_reports_unreadable_files() -> None:
    files = [("a.xml", PASSING), ("b.xml", FAILING), ("c.xml", b"<nonsense")]
    results = junit.package_results("pkg", files)
    root = ET.fromstring(junit.merged(results, files))
    assert root.tag == "testsuites" and root.get("name") == "pkg"
    assert {k: root.get(k) for k in ("tests", "failures", "errors", "skipped")} == {
        "tests": "5", "failures": "1", "errors": "1", "skipped": "0"}
    suites = root.findall("testsuite")
    assert [len(s.findall("testcase")) for s in suites] == [2, 2, 1]
    unreadable = suites[-1].find("testcase/error")
    assert unreadable is not None and unreadable.get("message", "").startswith("c.xml: not readable as XML")
    # read back, the merged file gives the same counts (what CI will show)
    again = junit.package_results("pkg", [("merged.xml", junit.merged(results, files))])
    assert (again.tests, again.failures, again.errors) == (5, 1, 1)


def test_pytest_real_junit_output(tmp_path: Path) -> None:
    """The format pytest writes today (what colcon asks it for), read end to end."""
    (tmp_path / "test_sample.py").write_text(
        "import pytest\n\n"
        "def test_passes():\n    assert 1 + 1 == 2\n\n"
        "def test_fails():\n    assert 'hello from talker #1' == 'hello #1'\n\n"
        "@pytest.mark.skip(reason='not here')\ndef test_skipped():\n    pass\n\n"
        "@pytest.fixture\ndef broken():\n    raise RuntimeError('fixture broke')\n\n"
        "def test_errors(broken):\n    pass\n"
    )
    xml = tmp_path / "pytest.xml"
    subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", f"--junit-xml={xml}",
                    "--junit-prefix=demo_talker", str(tmp_path / "test_sample.py")],
                   capture_output=True, cwd=tmp_path, timeout=120)
    results = junit.package_results("demo_talker", [("pytest.xml", xml.read_bytes())])
    outcomes = {c.name: c.outcome for c in results.cases}
    assert outcomes == {"test_passes": "passed", "test_fails": "failed", "test_skipped": "skipped",
                        "test_errors": "error"}
    failed = next(c for c in results.cases if c.name == "test_fails")
    assert failed.test_id == "demo_talker.test_sample::test_fails"
    assert "hello from talker #1" in failed.message and "hello #1" in failed.message
    errored = next(c for c in results.cases if c.name == "test_errors")
    assert "fixture broke" in errored.message or "RuntimeError" in errored.message
