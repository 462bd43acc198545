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


def merge_json_file(path, update):
    """Locked read-modify-write of the JSON object in `path`: `update` (a dict) is merged into it. A file that is not
    a JSON object is replaced. Returns the object written."""
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    with open(path + '.lock', 'w') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        content = {}
        try:
            with open(path) as f:
                content = json.load(f)
        except (OSError, ValueError):
            pass
        if not isinstance(content, dict):
            content = {}
        content.update(update)
        fd, temporary = tempfile.mkstemp(prefix='.' + os.path.basename(path) + '.', suffix='.partial', dir=folder)
        with os.fdopen(fd, 'w') as f:
            json.dump(content, f, indent=2, sort_keys=True)
            f.write('\n')
        os.replace(temporary, path)
    return content


def update_reliability(figures, bench_dir):
    """Merges `figures` (a dict) into bench_dir/reliability.json; returns the whole file's content after the merge."""
    return merge_json_file(os.path.join(bench_dir, 'reliability.json'), figures)


def record_bad_recordings(results, bench_dir):
    """Merges `results` ({recording name: survived (bool)}) into bench_dir/bad_recordings.json (the tests of bad
    recordings each fill in theirs) and sets bad_recordings_tried / bad_recordings_survived in reliability.json from
    every recording there. Returns (tried, survived)."""
    content = merge_json_file(os.path.join(bench_dir, 'bad_recordings.json'),
                              {name: bool(ok) for name, ok in results.items()})
    tried, survived = len(content), sum(1 for ok in content.values() if ok is True)
    update_reliability({'bad_recordings_tried': tried, 'bad_recordings_survived': survived}, bench_dir)
    return tried, survived
