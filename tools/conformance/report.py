"""Report writers: one text line per check, JUnit XML for CI systems, JSON for scripts."""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

from .results import CheckResult, Outcome, SuiteResult


def text_line(r: CheckResult) -> str:
    """One check as one line: outcome, name, what was seen."""
    return f"{r.outcome.value:<5} {r.name:<40} {r.detail}"


def summary(suite: SuiteResult) -> str:
    verdict = "CONFORMS" if suite.passed else "DOES NOT CONFORM"
    dev = suite.device
    who = f"{dev.get('model', '?')} serial {dev.get('serial', '?')} firmware {dev.get('firmware_version', '?')}"
    return (f"{verdict}: {who} at {suite.url}: {len(suite.results)} checks, {suite.count(Outcome.PASS)} passed, "
            f"{suite.count(Outcome.FAIL) + suite.count(Outcome.ERROR)} failed, {suite.count(Outcome.SKIP)} skipped "
            f"in {suite.duration_s:.1f} s")


def to_json(suite: SuiteResult) -> str:
    return json.dumps({
        "url": suite.url, "device": suite.device, "passed": suite.passed, "duration_s": round(suite.duration_s, 3),
        "counts": {o.value.lower(): suite.count(o) for o in Outcome},
        "checks": [{"name": r.name, "area": r.area, "outcome": r.outcome.value, "detail": r.detail,
                    "duration_s": round(r.duration_s, 3)} for r in suite.results],
    }, indent=2)


def write_junit(suite: SuiteResult, path: str | Path) -> None:
    """JUnit XML: one testsuite per area, one testcase per check (failure / error / skipped)."""
    root = ET.Element("testsuites", name="stereocam conformance", tests=str(len(suite.results)),
                      failures=str(suite.count(Outcome.FAIL)), errors=str(suite.count(Outcome.ERROR)),
                      skipped=str(suite.count(Outcome.SKIP)), time=f"{suite.duration_s:.3f}")
    areas: dict[str, ET.Element] = {}
    for r in suite.results:
        ts = areas.get(r.area)
        if ts is None:
            ts = areas[r.area] = ET.SubElement(root, "testsuite", name=f"conformance.{r.area}")
            props = ET.SubElement(ts, "properties")
            ET.SubElement(props, "property", name="url", value=suite.url)
            for key, value in suite.device.items():
                ET.SubElement(props, "property", name=key, value=str(value))
        case = ET.SubElement(ts, "testcase", classname=f"conformance.{r.area}", name=r.name, time=f"{r.duration_s:.3f}")
        if r.outcome is Outcome.FAIL:
            ET.SubElement(case, "failure", message=r.detail).text = r.detail
        elif r.outcome is Outcome.ERROR:
            ET.SubElement(case, "error", message=r.detail).text = r.detail
        elif r.outcome is Outcome.SKIP:
            ET.SubElement(case, "skipped", message=r.detail)
        else:
            ET.SubElement(case, "system-out").text = r.detail
    for ts in areas.values():
        cases = ts.findall("testcase")
        ts.set("tests", str(len(cases)))
        ts.set("failures", str(sum(c.find("failure") is not None for c in cases)))
        ts.set("errors", str(sum(c.find("error") is not None for c in cases)))
        ts.set("skipped", str(sum(c.find("skipped") is not None for c in cases)))
        ts.set("time", f"{sum(float(c.get('time', 0)) for c in cases):.3f}")
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
