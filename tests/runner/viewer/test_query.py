"""The viewer's address options (`static/query.js`) without a browser, under Node: `?show=` chooses the
motions and leaves the keyframes and contacts alone; `?hide=` unticks those; `?t=` is clamped."""
import json
import shutil
import subprocess

import pytest

from runner.viewer.server import STATIC

NODE = shutil.which("node") or shutil.which("nodejs")


def parse(search, t0=0.0, t1=2.0):
    """parseQuery(search, t0, t1) of query.js, run by Node."""
    if NODE is None:
        pytest.skip("node is not installed (apt-get install nodejs)")
    script = (f"import {{ parseQuery }} from {json.dumps((STATIC / 'query.js').as_uri())};"
              f"console.log(JSON.stringify(parseQuery({json.dumps(search)}, {t0}, {t1})));")
    done = subprocess.run([NODE, "--input-type=module", "-e", script], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_show_chooses_the_motions_only():
    q = parse("?show=optimized,plain")
    assert q["motions"] == {"optimized": True, "plain": True, "reference": False}
    assert q["overlays"] == {}  # keyframes and contacts keep their checkboxes
    assert q["time"] is None and q["unknown"] == []


def test_show_none_hides_every_motion_and_no_show_keeps_the_defaults():
    assert parse("?show=none")["motions"] == {"optimized": False, "plain": False, "reference": False}
    assert parse("")["motions"] is None
    assert parse("?t=1")["motions"] is None


def test_hide_unticks_keyframes_and_contacts():
    assert parse("?hide=keyframes")["overlays"] == {"keyframes": False}
    assert parse("?show=reference&hide=contacts,ghosts")["overlays"] == {"keyframes": False, "contacts": False}


def test_older_addresses_that_list_overlays_in_show_still_work():
    q = parse("?show=optimized,ghosts,contacts,keyframes")
    assert q["motions"] == {"optimized": True, "plain": False, "reference": False}
    assert q["overlays"] == {} and q["unknown"] == []


def test_unknown_names_are_reported():
    assert parse("?show=optimised&hide=floor")["unknown"] == ["optimised", "floor"]


@pytest.mark.parametrize("t, expected", [("1.1", 1.1), ("-3", 0.5), ("9", 2.0), ("abc", 0.5)])
def test_the_start_time_is_clamped_to_the_motions(t, expected):
    assert parse(f"?t={t}", t0=0.5, t1=2.0)["time"] == pytest.approx(expected)
