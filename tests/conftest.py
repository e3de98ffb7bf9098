"""Suite-wide rules: in CI (``CI`` set), a skip is a failure unless CI cannot provide what it needs.

Locally a test whose optional dependency is missing skips, naming the extra to install; CI installs
every extra (``make test``), so a skip there means a missing install step, not a passing test.
"""

from __future__ import annotations

import os

import pytest

# reasons a skip is allowed in CI: its machine has no GPU, and it runs as root (a test that needs a user
# without write permission has a twin that fakes the permission answer)
ALLOWED_SKIPS = ("CUDA", "needs a user")


def _in_ci() -> bool:
    return os.environ.get("CI", "").lower() not in ("", "0", "false")


def _allowed(reason: str) -> bool:
    return any(word in reason for word in ALLOWED_SKIPS)


def _reason(report) -> str:
    longrepr = report.longrepr
    return longrepr[2] if isinstance(longrepr, tuple) else str(longrepr)


def _fail_skip(report) -> None:
    reason = _reason(report)
    if report.skipped and _in_ci() and not _allowed(reason):
        report.outcome = "failed"
        report.longrepr = f"skipped in CI, where every extra is installed: {reason}"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if not hasattr(report, "wasxfail"):
        _fail_skip(report)


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    outcome = yield
    _fail_skip(outcome.get_result())
