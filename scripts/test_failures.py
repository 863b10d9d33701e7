#!/usr/bin/env python3
"""Print the failure messages of a test run's result files, last.

ctest prints a failing test's output where it fails, which a long log (or a
CI that shows only its end) buries. setup.sh calls this after a failing
ctest, so the end of the log names what failed and why: each failed test
case of the gtest and rostest result files written since the run started.

Usage: test_failures.py RESULTS_DIR [--since EPOCH_SECONDS]
"""
import argparse
import os
import sys
import xml.etree.ElementTree as ElementTree

LIMIT = 3000  # characters of one message; the whole is in the file


def failures(path):
    try:
        root = ElementTree.parse(path).getroot()
    except (ElementTree.ParseError, OSError) as error:
        yield ("(unreadable result file)", str(error))
        return
    for case in root.iter("testcase"):
        for tag in ("failure", "error"):
            for element in case.findall(tag):
                text = (element.get("message") or "") + "\n" + (element.text or "")
                name = (case.get("classname") or "") + "." + (case.get("name") or "")
                yield (name, text.strip())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results_dir")
    parser.add_argument("--since", type=float, default=0.0, help="only files written after this time")
    arguments = parser.parse_args()
    found = 0
    for directory, _, names in os.walk(arguments.results_dir):
        for name in sorted(names):
            path = os.path.join(directory, name)
            if not name.endswith(".xml") or os.path.getmtime(path) < arguments.since:
                continue
            for case, text in failures(path):
                found += 1
                if len(text) > LIMIT:
                    text = text[:LIMIT] + " [... cut; the whole is in " + path + "]"
                print("== failed: %s (%s)\n%s\n" % (case, name, text))
    if not found:
        print("== no failure recorded in the result files (a crash or a time limit: see the test's output above)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
