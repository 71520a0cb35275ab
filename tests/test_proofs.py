"""The integration suites' inventory (integration/proofs.txt) is what pytest collects there.

CI's time is a budget, and a faster CI is easy to get by losing a test. The inventory lists every integration test
by id; a test may leave it only as a "removed: ID: reason" line, so that a lost proof is a line a reviewer reads.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
INVENTORY = ROOT / "integration" / "proofs.txt"


def inventory() -> tuple[list[str], dict[str, str]]:
    """The inventory's test ids, in file order, and its removed ids with their reasons."""
    listed: list[str] = []
    removed: dict[str, str] = {}
    for line in INVENTORY.read_text(encoding="utf-8").splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        if line.startswith("removed: "):
            test_id, _, reason = line.removeprefix("removed: ").partition(": ")
            removed[test_id] = reason.strip()
        else:
            listed.append(line.strip())
    return listed, removed


def collected() -> list[str]:
    """The ids ``pytest --collect-only`` finds in integration/ (no Docker daemon is contacted to collect)."""
    proc = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
                           "integration"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return [line for line in proc.stdout.splitlines() if "::" in line and not line.startswith(" ")]


def test_every_collected_integration_test_is_in_the_inventory_and_none_went_missing() -> None:
    listed, _ = inventory()
    found = collected()
    assert len(found) == len(set(found)), "an id collected twice"
    new = sorted(set(found) - set(listed))
    missing = sorted(set(listed) - set(found))
    assert not new, "integration tests missing from integration/proofs.txt (add their lines):\n" + "\n".join(new)
    assert not missing, ("integration tests in integration/proofs.txt that pytest no longer collects; a test "
                         "leaves only as a 'removed: ID: reason' line:\n" + "\n".join(missing))


def test_the_inventory_is_sorted_and_every_removal_says_why() -> None:
    listed, removed = inventory()
    assert listed == sorted(listed), "keep integration/proofs.txt sorted, so that a diff shows one line per test"
    assert len(listed) == len(set(listed))
    assert all(removed.values()), f"a removal without its reason: {[k for k, v in removed.items() if not v]}"
    assert not set(removed) & set(listed), "an id both listed and removed"
