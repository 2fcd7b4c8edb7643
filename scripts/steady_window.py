"""Where the lab's steady window starts: one rule for the measured and the
predicted frame times (imported by the Python in scripts/farm-common.sh and
scripts/lab.sh).

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
