#!/usr/bin/python3
"""Snakemake cluster-status command: prints success, running or failed for a Slurm job id.

sacct where the cluster keeps accounting, else scontrol (which knows a job until MinJobAge after
it ends)."""
import subprocess
import sys

RUNNING = {"PENDING", "CONFIGURING", "RUNNING", "COMPLETING", "SUSPENDED", "REQUEUED",
           "RESIZING", "SIGNALING", "STAGE_OUT", "REQUEUE_FED"}


def run(command):
    try:
        out = subprocess.run(command, capture_output=True, text=True, timeout=20)
        return out.stdout if out.returncode == 0 else ""
    except (OSError, subprocess.TimeoutExpired):
        return ""


def state(job):
    """(state, reason) of the job; (None, "") when Slurm does not know it (or does not answer)."""
    lines = run(["sacct", "-j", job, "-X", "-n", "-P", "-o", "State,Reason"]).splitlines()
    if lines:
        state, _, reason = lines[0].partition("|")
        return state.split("+")[0], reason
    fields = dict(f.split("=", 1) for f in run(["scontrol", "show", "job", "-o", job]).split()
                  if "=" in f)
    return fields.get("JobState"), fields.get("Reason", "")


s, reason = state(sys.argv[1])
if s is None:
    print("running")  # not known yet, or Slurm busy: asked again later
elif s == "COMPLETED":
    print("success")
elif s in RUNNING and "held" not in reason.lower():
    print("running")
else:
    print("failed")  # FAILED, TIMEOUT, OUT_OF_MEMORY, CANCELLED, ..., or a launch failure held
