"""The reliability figures of the fault tests and the soak benchmark: out/bench/reliability.json, one file that several
tests fill in, each with its own keys (kills_tried, disk_full_survived, bad_recordings_tried, soak_..., multihost_...).

Each writer merges its keys into the file under an exclusive lock (read, update, write to a temporary, rename): the keys
of the others stay as they are, and a reader never sees half a file.
"""
import fcntl
import json
import os
import tempfile


def workspace_bench_dir(start_file):
    """<workspace>/out/bench for a file somewhere under the workspace (the first folder upwards that holds a
    .catkin_workspace), or $EXOCET_BENCH_DIR when set."""
    if os.environ.get('EXOCET_BENCH_DIR'):
        return os.environ['EXOCET_BENCH_DIR']
    folder = os.path.dirname(os.path.abspath(start_file))
    while folder != os.path.dirname(folder):
        if os.path.exists(os.path.join(folder, '.catkin_workspace')):
            return os.path.join(folder, 'out', 'bench')
        folder = os.path.dirname(folder)
    raise RuntimeError('no catkin workspace above %s: set EXOCET_BENCH_DIR' % start_file)


def update_reliability(figures, bench_dir):
    """Merges `figures` (a dict) into bench_dir/reliability.json; returns the whole file's content after the merge."""
    os.makedirs(bench_dir, exist_ok=True)
    path = os.path.join(bench_dir, 'reliability.json')
    with open(path + '.lock', 'w') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        content = {}
        if os.path.exists(path):
            try:
                with open(path) as f:
                    content = json.load(f)
            except ValueError:
                content = {}  # a file that is not JSON is replaced rather than merged into
            if not isinstance(content, dict):
                content = {}
        content.update(figures)
        fd, temporary = tempfile.mkstemp(prefix='.reliability.', suffix='.partial', dir=bench_dir)
        with os.fdopen(fd, 'w') as f:
            json.dump(content, f, indent=2, sort_keys=True)
            f.write('\n')
        os.replace(temporary, path)
    return content
