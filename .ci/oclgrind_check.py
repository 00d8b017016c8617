"""Oclgrind helpers for .ci/run (stdlib only, no rsocl import at module level).

python .ci/oclgrind_check.py scan LOG STDERR
    Exit 1 when Oclgrind reported anything. Oclgrind exits 0 even when it finds errors:
    kernel diagnostics (invalid read/write, data race, uninitialized value, work-group
    divergence, ...) go to OCLGRIND_LOG, which is empty on a clean run, so any text there
    is a failure; API misuse found by OCLGRIND_CHECK_API goes to stderr as blocks
    "Oclgrind - OpenCL runtime error detected". Only one kind of API report is
    allowed: clGetDeviceInfo -> CL_INVALID_VALUE for 'param_name', which is pyopencl
    probing vendor queries (CL_DEVICE_TOPOLOGY_AMD, ..._NV) that Oclgrind does not know.

python .ci/oclgrind_check.py device
    Check that rsocl, with the current environment (RSOCL_DEVICE / PYOPENCL_CTX), picks
    the Oclgrind device, i.e. that the tests really run under Oclgrind.

python .ci/oclgrind_check.py canary
    Positive control, run under the same environment as the tests: enqueue a kernel that
    writes one element past the end of its buffer on the Oclgrind device. The caller then
    scans the log and expects the scan to FAIL; this proves that the wiring (ICD, device
    selection, OCLGRIND_LOG) really catches errors on this machine.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

API_HEADER = "Oclgrind - OpenCL runtime error detected"
ALLOWED_API = re.compile(
    r"Function:\s*clGetDeviceInfo\s+Error:\s*CL_INVALID_VALUE\s+For argument 'param_name'\s*$", re.S)


def _blocks(text: str):
    """Paragraphs (blank-line separated) of an Oclgrind report stream."""
    return [block.strip() for block in re.split(r"\n\s*\n", text) if block.strip()]


def scan(log_path: str, stderr_path: str) -> int:
    log = Path(log_path).read_text(errors="replace") if Path(log_path).exists() else ""
    err = Path(stderr_path).read_text(errors="replace") if Path(stderr_path).exists() else ""
    problems = []

    log_blocks = _blocks(log)
    if log_blocks:
        # A report starts with an unindented line ("Invalid write of size 4 at ...", "Write-write
        # data race at ...", ...); data-race reports have indented/"First entity" sub-blocks.
        heads = [line for line in log.splitlines() if line.strip() and not line[0].isspace()
                 and not line.startswith(("First entity", "Second entity"))] or [b.splitlines()[0] for b in log_blocks]
        kinds = {}
        for head in heads:
            head = re.sub(r"0x[0-9a-fA-F]+", "0x…", head)
            kinds[head] = kinds.get(head, 0) + 1
        problems.append(f"{len(heads)} report(s) in the Oclgrind log {log_path}:")
        problems += [f"  {n:5d} x {first}" for first, n in sorted(kinds.items(), key=lambda kv: -kv[1])]
        problems.append("  first report:\n    " + log_blocks[0].replace("\n", "\n    "))

    allowed = 0
    api = []
    for block in err.split(API_HEADER)[1:]:
        body = block.strip().split("\n\n")[0].strip()
        if ALLOWED_API.match(body):
            allowed += 1
        else:
            api.append(body)
    if api:
        problems.append(f"{len(api)} OpenCL API error(s) reported by Oclgrind on stderr; first:\n    "
                        + api[0].replace("\n", "\n    "))
    # Kernel reports on stderr: Oclgrind falls back to stderr when OCLGRIND_LOG cannot be opened.
    stray = [line for line in err.splitlines()
             if re.search(r"^(Invalid (read|write)|.*data race|Uninitialized value|Work-group divergence)", line)]
    if stray:
        problems.append(f"{len(stray)} Oclgrind kernel report line(s) on stderr; first: {stray[0]}")

    print(f"oclgrind scan: log {len(log.strip().splitlines())} line(s); stderr: {allowed} allowed pyopencl "
          f"clGetDeviceInfo probe(s), {len(api)} other API error(s)")
    if problems:
        print("OCLGRIND FOUND PROBLEMS:\n" + "\n".join(problems), file=sys.stderr)
        return 1
    return 0


def device() -> int:
    from rsocl.device.context import get_device

    dev = get_device()
    print(f"rsocl device under the Oclgrind environment: {dev.name}")
    if "oclgrind" not in dev.name.lower():
        print("ERROR: rsocl did not pick the Oclgrind device; the tests would not run under Oclgrind",
              file=sys.stderr)
        return 1
    return 0


def canary() -> int:
    import numpy as np
    import pyopencl as cl

    from rsocl.device.context import get_device

    dev = get_device()
    assert "oclgrind" in dev.name.lower(), dev.name
    src = "__kernel void past_end(__global float *a) { size_t i = get_global_id(0); a[i + 1] = (float)i; }"
    prog = cl.Program(dev.context, src).build()
    buf = cl.Buffer(dev.context, cl.mem_flags.READ_WRITE, 4 * 4)
    prog.past_end(dev.queue, (4,), None, buf)
    out = np.empty(4, np.float32)
    cl.enqueue_copy(dev.queue, out, buf)
    dev.queue.finish()
    print("canary kernel ran (it writes a[4] of a 4-element buffer)")
    return 0


def main(argv) -> int:
    if len(argv) == 3 and argv[0] == "scan":
        return scan(argv[1], argv[2])
    if argv == ["device"]:
        return device()
    if argv == ["canary"]:
        return canary()
    print(__doc__, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
