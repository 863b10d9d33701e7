#!/usr/bin/env python3
"""Checks that the libraries' dependencies point down only (README "Architecture").

  * Every `#include "range_image_mapping/..."` (and every relative include
    "../<folder>/...") in src/<layer>/ and include/range_image_mapping/<layer>/
    names a layer that layer may use. Top-level range_image_mapping/*.h
    headers are the sensor layer; the generated message and service headers
    (msg/, srv/) belong to ros. src/tool (rim) may use anything.
  * Given the nodelet library, neither it nor what it loads (ldd) is the
    simulator, the evaluation or Embree, and it defines none of their symbols
    (in case they were linked in statically).
Exit status 1 with a list of violations, 0 when there are none.
Usage: check_layers.py REPOSITORY [NODELET_LIBRARY]
"""
import pathlib
import re
import subprocess
import sys

# Layer -> the layers its files may include (itself included).
ALLOWED = {
    "sensor": {"sensor"},
    "registration": {"registration", "sensor"},
    "mapping": {"mapping", "sensor"},
    "pipeline": {"pipeline", "registration", "mapping", "sensor"},
    "io": {"io", "sensor"},
    "simulation": {"simulation", "io", "sensor"},
    "evaluation": {"evaluation", "io", "sensor"},
    "ros": {"ros", "pipeline", "registration", "mapping", "io", "sensor"},
}
UNCHECKED_SOURCE_FOLDERS = {"tool"}
# What the nodelet library must not load: (ldd name part, symbol namespace).
NOT_IN_NODELETS = (("range_image_mapping_simulation", "range_image_mapping::simulation::"),
                   ("range_image_mapping_evaluation", "range_image_mapping::evaluation::"),
                   ("embree", None))

INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)


def generated_headers(repository):
    """The message and service headers catkin generates into range_image_mapping/."""
    names = set()
    for definition in list(repository.glob("msg/*.msg")) + list(repository.glob("srv/*.srv")):
        names.add(definition.stem + ".h")
        if definition.suffix == ".srv":
            names.update({definition.stem + "Request.h", definition.stem + "Response.h"})
    return names


def included_layer(include, generated):
    """The layer an include names, None for a header that is no layer's (a
    folder's own private header), or "?" plus the name for an unknown one."""
    parts = include.split("/")
    if parts[0] == "range_image_mapping":
        if len(parts) == 2:
            return "ros" if parts[1] in generated else "sensor"
        return parts[1] if parts[1] in ALLOWED else "?" + parts[1]
    if parts[0] == "..":
        folder = parts[1] if len(parts) > 2 else "?"
        return folder if folder in ALLOWED or folder in UNCHECKED_SOURCE_FOLDERS else "?" + folder
    return None


def layer_files(repository):
    """(layer, file) for every checked source and header."""
    headers = repository / "include" / "range_image_mapping"
    for path in sorted(headers.glob("*.h")):
        yield "sensor", path
    for folder in sorted(p for p in headers.iterdir() if p.is_dir()):
        for path in sorted(folder.rglob("*")):
            if path.is_file():
                yield folder.name, path
    for folder in sorted(p for p in (repository / "src").iterdir() if p.is_dir()):
        if folder.name in UNCHECKED_SOURCE_FOLDERS:
            continue
        for path in sorted(folder.rglob("*")):
            if path.is_file():
                yield folder.name, path


def include_violations(repository):
    generated = generated_headers(repository)
    problems = []
    for layer, path in layer_files(repository):
        where = path.relative_to(repository)
        if layer not in ALLOWED:
            problems.append("%s: folder %s is no known layer (add it to ALLOWED in %s)"
                            % (where, layer, pathlib.Path(__file__).name))
            continue
        if path.suffix not in (".h", ".hpp", ".cpp", ".cc"):
            continue
        text = path.read_text(errors="replace")
        for match in INCLUDE.finditer(text):
            used = included_layer(match.group(1), generated)
            if used is None or used in ALLOWED[layer]:
                continue
            line = text.count("\n", 0, match.start()) + 1
            if used.startswith("?"):
                problems.append('%s:%d: "%s" names no known layer' % (where, line, match.group(1)))
            else:
                problems.append('%s:%d: the %s layer includes "%s" (%s); it may use %s'
                                % (where, line, layer, match.group(1), used,
                                   ", ".join(sorted(ALLOWED[layer]))))
    return problems


def nodelet_library_violations(library):
    if not pathlib.Path(library).is_file():
        return ["%s: the nodelet library does not exist" % library]
    problems = []
    loaded = subprocess.run(["ldd", library], capture_output=True, text=True)
    if loaded.returncode != 0:
        return ["ldd %s failed: %s" % (library, loaded.stderr.strip())]
    symbols = subprocess.run(["nm", "-DC", "--defined-only", library], capture_output=True, text=True)
    if symbols.returncode != 0:
        return ["nm %s failed: %s" % (library, symbols.stderr.strip())]
    for name, namespace in NOT_IN_NODELETS:
        for line in loaded.stdout.splitlines():
            if name in line.split("=>")[0]:
                problems.append("%s loads %s" % (library, line.strip()))
        if namespace and namespace in symbols.stdout:
            problems.append("%s defines %s symbols (that layer is linked into it)" % (library, namespace))
    return problems


def main(argv):
    if len(argv) not in (2, 3):
        sys.exit(__doc__)
    repository = pathlib.Path(argv[1]).resolve()
    problems = include_violations(repository)
    if len(argv) == 3:
        problems += nodelet_library_violations(argv[2])
    for problem in problems:
        print(problem)
    if problems:
        print("%d layering violation(s); see the README's Architecture section" % len(problems))
        return 1
    print("layers point down only%s" % (" and the nodelet library loads no simulator, evaluation or Embree"
                                        if len(argv) == 3 else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
