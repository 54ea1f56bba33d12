"""The checks of the test scripts that ctest runs with Python (test_cost_model.py,
test_trace_summary.py, test_phase_summary.py): check() records and prints a failed
condition, finish() ends the script with exit status 1 when any failed."""
import sys

failures = []


def check(cond, what):
    if not cond:
        failures.append(what)
        print("FAIL:", what)


def finish(passed):
    """Exit status 1 after any failed check, else print `passed` and exit 0."""
    if failures:
        print(f"{len(failures)} failed")
        sys.exit(1)
    print(passed)
    sys.exit(0)
