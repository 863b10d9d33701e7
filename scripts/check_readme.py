#!/usr/bin/env python3
"""Checks README.md's nodelet reference against the code, so it cannot drift.

For each nodelet (Adapter, Odometry, Mapper):
  * every parameter read in src/ros/parameters.cpp (by its read<Name>Parameters
    function and the helpers it calls) has a row in the README's parameter
    table for that nodelet, and every row names a parameter the code reads;
  * every topic and service the nodelet advertises or subscribes to
    (src/ros/<name>_nodelet.cpp) is named in its README section.
Exit status 1 with a list of differences, 0 when they agree.
Usage: check_readme.py [REPOSITORY]   (default: the folder above this script)
"""
import pathlib
import re
import sys

NODELETS = ("Adapter", "Odometry", "Mapper")


def function_bodies(source):
    """Top-level function name -> body text, found by matching braces."""
    bodies = {}
    for match in re.finditer(r"^[\w:<>,\s&*]*?\b(\w+)\(([^;{]*?)\)\s*(?:const\s*)?\{", source, re.M):
        depth, index = 1, match.end()
        while depth and index < len(source):
            depth += {"{": 1, "}": -1}.get(source[index], 0)
            index += 1
        bodies.setdefault(match.group(1), source[match.end():index])
    return bodies


def parameters_in_code(parameters_cpp, nodelet):
    bodies = function_bodies(parameters_cpp)
    names, seen = set(), set()
    pending = ["read%sParameters" % nodelet]
    while pending:
        function = pending.pop()
        if function in seen or function not in bodies:
            continue
        seen.add(function)
        body = bodies[function]
        names.update(re.findall(r'reader\.get\w+\(\s*"([^"]+)"', body))
        # getOrderedDoubles reads two parameters: the lower's name first, the upper's third.
        for lower, upper in re.findall(r'reader\.getOrderedDoubles\(\s*"([^"]+)",[^,]+,\s*"([^"]+)"', body):
            names.update((lower, upper))
        pending.extend(name for name in re.findall(r"\b(read\w+)\(", body) if name in bodies)
    return names


def interfaces_in_code(nodelet_cpp):
    patterns = (
        r'advertise<[^>]*>\(\s*"([^"]+)"',
        r'advertiseService\(\s*"([^"]+)"',
        r'subscribe\(\s*"([^"]+)"',
        r'Subscriber<[^>]*>>\([^,]+,\s*"([^"]+)"',
    )
    return {name for pattern in patterns for name in re.findall(pattern, nodelet_cpp)}


def readme_section(readme, nodelet):
    """Text from the heading naming range_image_mapping/<nodelet> to the next heading of that level or above."""
    heading = re.search(r"^(#+) .*`range_image_mapping/%s`.*$" % nodelet, readme, re.M)
    if not heading:
        return None
    level = len(heading.group(1))
    end = re.compile(r"^#{1,%d} " % level, re.M).search(readme, heading.end())
    return readme[heading.end():end.start() if end else len(readme)]


def parameters_in_readme(section):
    names, in_table = set(), False
    for line in section.splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")] if line.startswith("|") else None
        if cells is None:
            in_table = False
            continue
        if cells[0] == "parameter":
            in_table = True
            continue
        if in_table and not set(cells[0]) <= set("-: "):
            names.update(re.findall(r"`([^`]+)`", cells[0]))
    return names


def main():
    repository = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).resolve().parent.parent)
    readme = (repository / "README.md").read_text()
    parameters_cpp = (repository / "src/ros/parameters.cpp").read_text()
    problems = []
    for nodelet in NODELETS:
        section = readme_section(readme, nodelet)
        if section is None:
            problems.append("README.md has no section headed with `range_image_mapping/%s`" % nodelet)
            continue
        code = parameters_in_code(parameters_cpp, nodelet)
        documented = parameters_in_readme(section)
        if not code:
            problems.append("found no parameters read by read%sParameters in src/ros/parameters.cpp" % nodelet)
        for name in sorted(code - documented):
            problems.append("%s parameter `%s` is read by the code but not in the README table" % (nodelet, name))
        for name in sorted(documented - code):
            problems.append("%s parameter `%s` is in the README table but the code does not read it" % (nodelet, name))
        nodelet_cpp = (repository / ("src/ros/%s_nodelet.cpp" % nodelet.lower())).read_text()
        named = set(re.findall(r"`~?([^`]+)`", section))
        for name in sorted(interfaces_in_code(nodelet_cpp) - named):
            problems.append("%s topic or service `%s` is not named in its README section" % (nodelet, name))
    for problem in problems:
        print("README.md: " + problem)
    if not problems:
        print("README.md matches the code: parameters, topics and services of %s" % ", ".join(NODELETS))
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
