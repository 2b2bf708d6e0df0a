"""What the load scripts of bench/ share (stop_latency.py, thread_load.py): busy processes
beside a measurement, so its figures are those of a loaded machine, and the CSV of its rows.
"""
import contextlib
import csv
import multiprocessing


def spin():
    """A pure Python busy loop: one core's worth of load until terminated."""
    while True:
        pass


@contextlib.contextmanager
def busy_loops(count):
    """`count` processes running spin() for the block; each is terminated and reaped after it,
    whatever the way out."""
    spinners = [multiprocessing.Process(target=spin, daemon=True) for _ in range(count)]
    for s in spinners:
        s.start()
    try:
        yield
    finally:
        for s in spinners:
            s.terminate()
            s.join()


def write_rows(path, rows):
    """`rows` (dicts with the same keys, at least one) as CSV at `path`: the first row's keys
    are the header, a line per row."""
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
