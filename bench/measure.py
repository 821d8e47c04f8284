"""Runs one command and records its wall time, CPU time and its own peak RSS.

    python -I -S measure.py RESULT.json TIMEOUT_S COMMAND [ARGS...]

Why a separate, lean launcher: Linux folds the resident size of the address space a child
had before exec (a copy of its parent's) into the child's ru_maxrss. Forked from the
benchmark process (numpy, VTK, a mesh or two in memory) a 40 MiB isobar run reads as the
parent's 130 MiB. Forked from this stdlib-only process, the floor is this process's few
MiB, and ru_maxrss above it is the command's own peak.
"""

import json
import os
import signal
import sys
import time


def vm_hwm_kib() -> int:
    """Peak resident size of this process's own address space (VmHWM), in KiB."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1])
    return -1


def main() -> None:
    result_path, timeout, cmd = sys.argv[1], float(sys.argv[2]), sys.argv[3:]
    t0 = time.perf_counter()
    pid = os.fork()
    if pid == 0:
        try:
            os.execvp(cmd[0], cmd)
        except OSError as e:
            print(f"measure.py: cannot run {cmd[0]}: {e}", file=sys.stderr)
        os._exit(127)
    timed_out = False

    def on_alarm(_signum, _frame):
        nonlocal timed_out
        timed_out = True
        os.kill(pid, signal.SIGKILL)

    signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout)
    _, status, usage = os.wait4(pid, 0)
    signal.setitimer(signal.ITIMER_REAL, 0)
    result = {
        "exit_code": os.waitstatus_to_exitcode(status),
        "wall_s": time.perf_counter() - t0,
        "peak_rss_kib": usage.ru_maxrss,
        "cpu_s": usage.ru_utime + usage.ru_stime,
        # The floor under peak_rss_kib (RUSAGE_SELF would report the parent's size too).
        "launcher_hwm_kib": vm_hwm_kib(),
        "timed_out": timed_out,
    }
    with open(result_path, "w") as f:
        json.dump(result, f)


if __name__ == "__main__":
    main()
