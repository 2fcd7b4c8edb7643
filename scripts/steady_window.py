"""The lab's steady window: one rule for the measured and the predicted
frame times (imported by the Python in scripts/farm-common.sh and
scripts/lab.sh). Rates are timed by completions at the master
(`completions`, `seconds_per_frame`); the CPU samples, taken at arrivals,
by the bunch rule below.

Frames complete in order, so on a farm of unequal workers the frames a fast
worker finished wait for a slow worker's and reach the submitter in a bunch,
one bunch per slow frame. A window that starts inside a bunch counts the
bunch's later frames in almost no time and overstates the rate; one that
starts at a bunch's last frame and ends at the last frame (a bunch's end
too) counts whole bunches only."""


def bunch_end(times, k):
    """The last arrival of the bunch that holds arrival `k`: the arrivals
    after it whose gap to the one before is under a quarter of the mean gap
    from `k` on. `times` are the arrival times, ascending. Gives `k` itself
    when the bunch would reach the last arrival (no window would be left)."""
    last = len(times) - 1
    if k >= last:
        return k
    mean_gap = (times[last] - times[k]) / (last - k)
    end = k
    while end < last and times[end + 1] - times[end] < mean_gap / 4:
        end += 1
    return end if end < last else k


def completions(frames):
    """Each frame's completion at the master (its last result in), in
    seconds on the submitter's clock, ascending, from `vtfarm submit`'s
    stats.json frames. The master finishes a job's frames in order, so on
    a farm of unequal workers a frame done early waits for those before
    it, and arrivals bunch behind a slow worker's frames; completions do
    not. A frame's `wall_micros` runs from its first assignment to its
    finish, held time included; its workers' phases (master time from the
    frame's start) span its first assignment to its last result: the
    arrival less the wall plus that span. A frame without worker phases
    (one resumed from the journal) counts at its arrival."""
    times = []
    for f in frames:
        phases = [p for p in f.get("phases", []) if p["who"] != "master"]
        at = f["arrival_micros"]
        if phases:
            span = max(p["end_micros"] for p in phases) - min(p["start_micros"] for p in phases)
            at = at - f["wall_micros"] + min(span, f["wall_micros"])
        times.append(at / 1e6)
    return sorted(times)

def seconds_per_frame(times, k):
    """The mean time per frame from the `k`-th of `times` (ascending) to
    the last: the steady window over the frames after the first `k`."""
    last = len(times) - 1
    if k >= last:
        raise ValueError(f"{len(times)} times leave no window after the {k}-th")
    return (times[last] - times[k]) / (last - k)
