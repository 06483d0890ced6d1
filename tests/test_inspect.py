"""inspect: .rrd files read back with RrdReader (entity paths, archetypes, counts),
the web viewer answering on its port and stopping on Ctrl-C, one-line errors.

Inputs are the sample logs compiled into a tree plus a replay of that tree when the
sample logs exist; otherwise a short simulated demonstration and a hand-made tree.
"""

from __future__ import annotations

import os
import re
import select
import signal
import subprocess
import sys
import time
import urllib.request
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from conftest import smc_start  # noqa: E402
from rerun.chunk import RrdReader  # noqa: E402

from smccli.errors import LogError, SmcError, TreeError  # noqa: E402
from smccli.inspect.labels import branch_colours  # noqa: E402
from smccli.inspect.recording import inspect  # noqa: E402
from smccli.learn.tree import load_tree  # noqa: E402
from smccli.logs import read_log  # noqa: E402
from smccli.perception.colours import colour_name, dominant_rgb  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
SAMPLES = Path(os.environ.get("SMC_SAMPLE_LOGS", REPO / "sample_logs"))
"""Sample logs; point SMC_SAMPLE_LOGS at an empty folder to test the simulated fallback."""
PY = sys.executable


@dataclass(frozen=True)
class Inputs:
    tree: Path
    demos: list[Path]
    replay: Path
    weighed: tuple[Path, Path] | None
    """A tree and a log with a scale (weigh_sort), when the sample logs exist."""


# --- inputs -------------------------------------------------------------------------------


def _simulated_demo(path: Path, *, decisions: bool) -> None:
    """A 3 s pick_place run: approach and close on the orange cube, lift; two marks; a
    synthetic scale reading; with ``decisions`` two /smc/decision records (a replay)."""
    from smccli.logs import LogWriter
    from smccli.logs import topics as tp
    from smccli.logs.writer import scene_attachments
    from smccli.world.layout import nominal_layout
    from smccli.world.scene import load_scene
    from smccli.world.sensors import PoiCommand, SaliencyMark
    from smccli.world.sim import Sim

    scene = load_scene("pick_place")
    layout = nominal_layout(scene, scene.variants[0][0] if scene.variants else None)
    sim = Sim(scene, layout)
    cube = np.array(layout["orange_cube"][:3])
    start = sim.poi()
    above = np.r_[cube[:2], cube[2] + 0.12, start[3]]
    at = np.r_[cube[:2], cube[2], start[3]]
    with LogWriter(
        path,
        metadata={"scene": scene.name, "operator": "test"},
        attachments=scene_attachments(scene),
        wall_clock_flush=False,
    ) as w:
        for k in range(300):
            t = sim.t
            s = min(k / 120, 1.0)
            if k < 150:
                target = (1 - s) * start + s * above
            else:
                target = above + (at - above) * min((k - 150) / 80, 1.0)
            grip = 1.0 if k < 240 else 0.0
            if k % 10 == 0:
                w.write_camera(sim.render_camera())
            if k in (150, 260):
                w.write_saliency(SaliencyMark(t, "operator", "approach" if k == 150 else "grasp"))
            if decisions and k in (0, 150):
                w.write_json(
                    tp.DECISION,
                    t,
                    {
                        "node": "n0" if k == 0 else "n1",
                        "candidates": [
                            {"edge": "e1" if k == 0 else "e2", "d_p": 0.02, "contingent": True}
                        ],
                        "chosen": "e1" if k == 0 else "e2",
                        "mapped_goal": (above if k == 0 else at).tolist(),
                    },
                )
            cmd = PoiCommand(t, target, grip)
            w.write_command(cmd)
            sim.step(cmd)
            w.write_joint_state(sim.joint_state())
            w.write_poi(sim.t, sim.poi())
            w.write_weight(sim.t, 0.0 if k < 200 else 0.25)
    sim.close()


def _hand_made_tree(log_path: Path, out: Path) -> None:
    """Two SMCs fitted on the demo's command path (approach, grasp), the cube as cluster."""
    from smccli.learn import dmp
    from smccli.learn.frames import goal_in_object
    from smccli.learn.params import SmcParams
    from smccli.learn.smc import Action, SalientPerceptions, Smc, Source
    from smccli.learn.tree import Tree, insert_chain, save_tree
    from smccli.perception import Cluster
    from smccli.perception.histogram import histogram_size

    log = read_log(log_path)
    params = SmcParams()
    hist = np.zeros(histogram_size(params.perception))
    hist[1 * params.perception.sat_bins + 2] = 1.0  # orange, saturated
    t = np.array([c.t for c in log.commands])
    y = np.array([c.target for c in log.commands])
    cube = Cluster(
        centroid=y[-1, :3].copy(),
        yaw=0.0,
        yaw_period=np.pi / 2,
        extents=np.array([0.05, 0.05, 0.05]),
        histogram=hist,
        n_points=400,
    )
    chain, sources = [], []
    for (a, b), grip in (((0.0, 1.5), (1.0, 1.0)), ((1.5, 3.0), (1.0, 0.0))):
        sel = (t >= a) & (t <= b)
        d = dmp.fit(t[sel] - t[sel][0], y[sel], params.dmp)
        action = Action(
            dmp=d,
            goal_frame="object",
            goal=goal_in_object(y[sel][-1], cube),
            gripper_start=grip[0],
            gripper_end=grip[1],
        )
        chain.append(Smc(SalientPerceptions(cluster=cube, weight=0.0), action))
        sources.append(Source(log=log_path.name, sha256=log.sha256, t0=a, t1=b))
    tree = insert_chain(Tree(params=params, scene={"name": "pick_place"}), chain, sources)
    save_tree(tree, out)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Inputs:
    """Sample logs + compiled tree + a replay when present, else simulated inputs."""
    root = tmp_path_factory.mktemp("inspect")
    demos = sorted((SAMPLES / "pick_place").glob("*.mcap"))
    if len(demos) >= 2:
        from smccli.execute import run_episode
        from smccli.learn.compile import compile_logs

        tree = root / "pick_place.json"
        compile_logs(demos, tree)
        replay = root / "replay.mcap"
        run_episode(tree, scene=None, seed=0, layout=None, output=replay, report=None, force=True)
        weighed = None
        light = SAMPLES / "weigh_sort" / "demo_light.mcap"
        if light.is_file():
            wtree = root / "weigh_sort.json"
            compile_logs([light], wtree)
            weighed = (wtree, light)
        return Inputs(tree, demos, replay, weighed)
    demo = root / "demo.mcap"
    _simulated_demo(demo, decisions=False)
    replay = root / "replay.mcap"
    _simulated_demo(replay, decisions=True)
    tree = root / "tree.json"
    _hand_made_tree(demo, tree)
    return Inputs(tree, [demo], replay, (tree, demo))


# --- reading an .rrd back ---------------------------------------------------------------


def read_rrd(path: Path) -> dict[str, dict[str, dict]]:
    """recording id -> entity path -> {"archetypes", "rows", "columns": {name: [rows]}}."""
    reader = RrdReader(path)
    out: dict[str, dict[str, dict]] = {}
    for store in reader.recordings():
        ents: dict[str, dict] = defaultdict(
            lambda: {"archetypes": set(), "rows": 0, "columns": defaultdict(list)}
        )
        for chunk in reader.stream(store=store):
            e = ents[chunk.entity_path]
            batch = chunk.to_record_batch()
            e["rows"] += chunk.num_rows
            for name in batch.schema.names:
                if ":" in name:
                    e["archetypes"].add(name.split(":")[0])
                    e["columns"][name].extend(batch.column(name).to_pylist())
        out[store.recording_id] = dict(ents)
    return out


def _instances(entity: dict, column: str) -> list:
    """All instances of a component column, flattened over rows."""
    return [v for row in entity["columns"][column] if row is not None for v in row]


def _check_tree(rec: dict, tree_path: Path) -> None:
    tree = load_tree(tree_path)
    assert {"GraphNodes", "GraphEdges"} <= rec["/tree"]["archetypes"]
    ids = _instances(rec["/tree"], "GraphNodes:node_ids")
    texts = dict(zip(ids, _instances(rec["/tree"], "GraphNodes:labels"), strict=True))
    colours = dict(zip(ids, _instances(rec["/tree"], "GraphNodes:colors"), strict=True))
    # Decision points, then per SMC a label and a colour swatch, all in one entity.
    edge_ids = [e.id for e in tree.edges]
    assert sorted(ids) == sorted([*tree.nodes, *edge_ids, *(f"{e} colour" for e in edge_ids)])
    edges = _instances(rec["/tree"], "GraphEdges:edges")
    assert len(edges) == len(tree.edges)
    # Text in one neutral grey (it takes the node's colour): readable on both themes.
    assert len({colours[n] for n in [*tree.nodes, *edge_ids]}) == 1
    for e in tree.edges:
        text = texts[e.id]
        assert text.startswith(f"{e.id}:")
        assert e.smc.action.event in text and f"support {e.support}" in text
        assert e.sources[0].log in text
        if e.smc.perception.cluster is not None:
            assert "object" in text
            rgb = dominant_rgb(e.smc.perception.cluster.histogram)
            packed = (rgb[0] << 24) | (rgb[1] << 16) | (rgb[2] << 8) | 0xFF
            assert colours[f"{e.id} colour"] == packed, "the swatch has the object's colour"
    # The layout keeps labels apart: no two label boxes overlap.
    from smccli.inspect.views import graph_layout, text_size

    layout = graph_layout(tree, {e.id: texts[e.id] for e in tree.edges})
    boxes = [(layout.labels[e.id], text_size(texts[e.id])) for e in tree.edges]
    for i, ((x1, y1), (w1, h1)) in enumerate(boxes):
        for (x2, y2), (w2, h2) in boxes[i + 1 :]:
            assert abs(x1 - x2) >= (w1 + w2) / 2 or abs(y1 - y2) >= (h1 + h2) / 2
    (x0, x1), (y0, y1) = layout.bounds
    for x, y in [*layout.nodes.values(), *layout.labels.values(), *layout.swatches.values()]:
        assert x0 < x < x1 and y0 < y < y1, "the view opens on the whole tree"
    for e in tree.edges:
        assert rec[f"/world/actions/{e.id}"]["archetypes"] == {"LineStrips3D"}
        assert "Points3D" in rec[f"/world/actions/{e.id}/goal"]["archetypes"]
    assert "TextDocument" in rec["/tree/smcs"]["archetypes"]


# --- tests --------------------------------------------------------------------------------


def test_tree_alone(inputs, tmp_path):
    out = tmp_path / "tree.rrd"
    result = inspect(inputs.tree, [], save=out)
    data = read_rrd(out)
    assert list(data) == list(result.recordings) and len(data) == 1
    _check_tree(next(iter(data.values())), inputs.tree)
    assert len(RrdReader(out).blueprints()) == 1


def test_demos_and_replay_each_get_a_recording(inputs, tmp_path):
    out = tmp_path / "all.rrd"
    logs = [*inputs.demos, inputs.replay]
    result = inspect(inputs.tree, logs, save=out)
    data = read_rrd(out)
    assert sorted(data) == sorted(result.recordings) and len(data) == len(logs)
    for path, rid in zip(logs, result.recordings, strict=True):
        rec, log = data[rid], read_log(path)
        _check_tree(rec, inputs.tree)
        assert rec["/world/poi"]["rows"] == len(log.poi_t)
        assert rec["/world/poi/path"]["archetypes"] == {"LineStrips3D"}
        assert rec["/signals/poi/z"]["rows"] == len(log.poi_t)
        assert rec["/signals/gripper"]["rows"] == len(log.commands)
        assert rec["/world/camera/image"]["rows"] == len(log.frames)
        assert "DepthImage" in rec["/world/camera/depth"]["archetypes"]
        assert {"Pinhole", "Transform3D"} <= rec["/world/camera"]["archetypes"]
        _check_robot(rec, log)
        # One event per saliency mark.
        if log.marks:
            assert rec["/events/saliency"]["archetypes"] == {"TextLog"}
            texts = _instances(rec["/events/saliency"], "TextLog:text")
            assert len(texts) == len(log.marks)
        else:
            assert "/events/saliency" not in rec
        # Clouds and clusters at every decision point, the salient one highlighted.
        n_points = rec["/world/decisions/cloud"]["rows"]
        assert n_points >= 1 and rec["/world/decisions/clusters"]["rows"] == n_points
        assert "Boxes3D" in rec["/world/decisions/salient"]["archetypes"]
        if log.decisions:
            assert n_points == len(log.decisions)
            texts = _instances(rec["/events/decisions"], "TextLog:text")
            assert len(texts) == len(log.decisions)
            for d, text in zip(log.decisions, texts, strict=True):
                assert f"chose {d['chosen']}" in text
                for c in d["candidates"]:
                    assert str(c["edge"]) in text
                    if c.get("d_p") is not None:
                        assert f"/signals/decision/d_p/{c['edge']}" in rec
            assert rec["/world/decisions/goal"]["rows"] == len(log.decisions)
            assert "LineStrips3D" in rec["/world/decisions/planned"]["archetypes"]
        else:
            assert "/events/decisions" not in rec
            assert rec["/events/fragments"]["rows"] == n_points


def _check_robot(rec: dict, log) -> None:
    """Every moving body of the robot posed over time (at most RATE Hz), drawn from its
    geoms; the fingers end where the POI ends."""
    from smccli.inspect.robot_view import RATE
    from smccli.logs.robot import robot_model_of

    model = robot_model_of(log)
    duration = log.joint_states[-1].t - log.joint_states[0].t
    for b in model.bodies:
        name = model.model.body(int(b)).name
        ent = rec[f"/world/robot/{name}"]
        assert "Transform3D" in ent["archetypes"]
        assert 0.8 * duration * RATE <= ent["rows"] <= duration * RATE + 2
    shapes = set().union(
        *(e["archetypes"] for path, e in rec.items() if path.startswith("/world/robot/"))
    )
    assert shapes & {"Boxes3D", "Capsules3D", "Cylinders3D", "Ellipsoids3D", "Mesh3D"}
    fingers = [p for p in rec if p.startswith("/world/robot/finger") and p.count("/") == 3]
    last = np.array(rec[fingers[0]]["columns"]["Transform3D:translation"][-1]).reshape(-1)
    assert np.linalg.norm(last - log.poi[-1, :3]) < 0.12


def test_weight_is_a_signal(inputs, tmp_path):
    assert inputs.weighed is not None
    tree, log_path = inputs.weighed
    out = tmp_path / "w.rrd"
    inspect(tree, [log_path], save=out)
    rec = next(iter(read_rrd(out).values()))
    log = read_log(log_path)
    assert len(log.weight) > 0
    assert rec["/signals/weight"]["archetypes"] == {"Scalars"}
    assert rec["/signals/weight"]["rows"] == len(log.weight)


def test_colours_and_branches(inputs):
    assert colour_name((255, 128, 0)) == "orange"
    assert colour_name((240, 240, 240)) == "white"
    hist = np.zeros(12 * 3 + 3)
    hist[4 * 3 + 2] = 1.0  # hue bin 4 of 12: green
    assert colour_name(dominant_rgb(hist)) == "green"
    tree = load_tree(inputs.tree)
    colours = branch_colours(tree)
    assert set(colours) == {e.id for e in tree.edges}
    for e in tree.edges:  # a chain keeps its colour; a fork's children differ
        kids = tree.children(e.child)
        if len(kids) == 1:
            assert colours[kids[0].id] == colours[e.id]
        elif len(kids) > 1:
            assert len({colours[k.id] for k in kids}) == len(kids)


def test_default_save_next_to_the_tree(inputs, tmp_path):
    tree = tmp_path / "t.json"
    tree.write_bytes(inputs.tree.read_bytes())
    proc = subprocess.run(
        [PY, "-m", "smccli.cli", "inspect", str(tree)],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "t.rrd").is_file()
    _check_tree(next(iter(read_rrd(tmp_path / "t.rrd").values())), tree)


def _descendants(pid: int) -> set[int]:
    out: set[int] = set()
    todo = [pid]
    while todo:
        p = todo.pop()
        for task in Path(f"/proc/{p}/task").glob("*"):
            try:
                kids = (task / "children").read_text().split()
            except OSError:
                continue
            for k in map(int, kids):
                if k not in out:
                    out.add(k)
                    todo.append(k)
    return out


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_serve_answers_and_ctrl_c_stops_everything(inputs, tmp_path):
    port = _free_port()
    proc = subprocess.Popen(
        [
            PY,
            "-m",
            "smccli.cli",
            "inspect",
            str(inputs.tree),
            str(inputs.demos[0]),
            "--serve",
            "--port",
            str(port),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    children: set[int] = set()
    try:
        # The address is printed once the viewer answers; read it, then ask the port.
        deadline = time.monotonic() + 60
        seen = ""
        while not re.search(rf"http://127\.0\.0\.1:{port}\b", seen):
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, f"no address printed: {seen!r}"
            ready, _, _ = select.select([proc.stdout], [], [], 1.0)
            if ready:
                seen += proc.stdout.readline()
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=5) as r:
            assert r.status == 200
            assert b"<html" in r.read(4096).lower()
        children = _descendants(proc.pid)
        assert children, "the web viewer runs as a child process"
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        for pid in children:
            assert not _alive(pid), f"child {pid} still running"
        with pytest.raises(OSError):
            urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=2)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for pid in children:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)


def _bad_inputs(tmp: Path, good_tree: Path, good_log: Path) -> dict[str, tuple[list[str], str]]:
    corrupt_tree = tmp / "corrupt.json"
    corrupt_tree.write_text('{"format": "smc-tree", "nodes": [')
    edited = tmp / "edited.json"
    edited.write_text(good_tree.read_text().replace('"support": 1', '"support": 7', 1))
    corrupt_log = tmp / "corrupt.mcap"
    corrupt_log.write_bytes(b"\x89MCAP0\r\n" + os.urandom(200))
    not_mcap = tmp / "notes.mcap"
    not_mcap.write_text("hello")
    return {
        "missing tree": ([str(tmp / "nope.json")], "nope.json"),
        "corrupt tree": ([str(corrupt_tree)], "corrupt.json"),
        "edited tree": ([str(edited)], "edited.json"),
        "missing log": ([str(good_tree), str(tmp / "gone.mcap")], "gone.mcap"),
        "corrupt log": ([str(good_tree), str(corrupt_log)], "corrupt.mcap"),
        "not a log": ([str(good_tree), str(not_mcap)], "notes.mcap"),
    }


def test_bad_tree_or_log_is_one_line_and_exit_code_2(inputs, tmp_path):
    cases = _bad_inputs(tmp_path, inputs.tree, inputs.demos[0])
    procs = {  # side by side
        name: smc_start(
            "inspect",
            *args,
            "--save",
            tmp_path / f"{i}.rrd",
            out=tmp_path / f"{i}.out",
            err=tmp_path / f"{i}.err",
            env={**os.environ, "COLUMNS": "400"},
        )
        for i, (name, (args, _)) in enumerate(cases.items())
    }
    for name, p in procs.items():
        out, err = p.communicate(timeout=60)
        lines = err.strip().splitlines()
        assert p.returncode == 2, (name, err)
        assert len(lines) == 1, (name, err)
        assert "Traceback" not in err and cases[name][1] in lines[0], (name, err)
        assert not list(tmp_path.glob("*.rrd")), (name, "no output on error")


def test_a_readable_log_without_a_topic_is_shown_with_a_warning(inputs, tmp_path):
    """A viewer shows what a log holds (docs/logs.md, errors): a log without its camera, or
    without its scene attachment, is written with one warning line naming what is
    missing, exit 0; the recording holds what the log does hold."""
    from smccli.logs import strip_topic

    no_camera = strip_topic(inputs.demos[0], tmp_path / "no_camera.mcap", "/camera/color")
    rrd = tmp_path / "no_camera.rrd"
    p = subprocess.run(
        [PY, "-m", "smccli.cli", "inspect", str(inputs.tree), str(no_camera), "--save", str(rrd)],
        capture_output=True,
        text=True,
        env={k: v for k, v in os.environ.items() if k != "COLUMNS"},
    )
    assert p.returncode == 0, p.stderr
    lines = p.stderr.splitlines()
    assert lines == [
        f"warning: {no_camera}: no /camera/color: shown without (compile would refuse it)"
    ]
    (entities,) = read_rrd(rrd).values()
    assert {"/tree", "/world/poi", "/world/perception/points"} <= set(entities)
    assert not [e for e in entities if "camera" in e], sorted(entities)


def test_library_errors_are_typed(inputs, tmp_path):
    with pytest.raises(TreeError, match="nope.json"):
        inspect(tmp_path / "nope.json", [], save=tmp_path / "x.rrd")
    with pytest.raises(LogError, match="gone.mcap"):
        inspect(inputs.tree, [tmp_path / "gone.mcap"], save=tmp_path / "x.rrd")
    with pytest.raises(SmcError, match="exactly one"):
        inspect(inputs.tree, [], save=tmp_path / "x.rrd", serve=True)
    assert not (tmp_path / "x.rrd").exists()


@pytest.mark.slow
def test_web_viewer_draws_in_a_real_browser(inputs, tmp_path):
    """`smc inspect --serve` opened in Chromium (Playwright, WebGL on the CPU): the page
    draws the tree (every swatch colour in the graph view), the demonstrated paths (a
    branch colour in the 3D view) and the first log's camera (the camera view shows its
    last frame, closer to it than to the second log's); both addresses are printed
    plainly, the data port is the one asked for; Ctrl-C leaves no process behind."""
    from smccli.bench.viewer import (
        CAMERA,
        browser_page,
        image_distance,
        image_in_panel,
        page_drawn,
        serving,
        wait_for,
        webgl_url,
    )

    assert len(inputs.demos) >= 2, "needs the pick_place sample logs"
    first, second = (read_log(p).frames[-1].rgb for p in inputs.demos[:2])
    drawn = page_drawn(load_tree(inputs.tree), first)

    port, grpc = _free_port(), _free_port()
    before = _descendants(os.getpid())
    with serving(inputs.tree, inputs.demos[:2], port=port, grpc_port=grpc) as served:
        assert served.viewer.startswith(f"http://127.0.0.1:{port}/?url=")
        assert served.data == f"rerun+http://127.0.0.1:{grpc}/proxy"
        children = _descendants(served.proc.pid)
        assert children, "the web viewer runs as a child process"
        with browser_page() as page:
            page.goto(webgl_url(served.viewer), timeout=180_000)
            image = wait_for(page, drawn, timeout=600)
        shown = image_in_panel(CAMERA.crop(image))
        assert shown is not None
        assert image_distance(shown, first) < image_distance(shown, second), (
            "the page opens on the first log's recording"
        )
    assert served.proc.returncode == 0, served.proc.stderr.read() if served.proc.stderr else ""
    for pid in children:
        assert not _alive(pid), f"viewer process {pid} still running"
    left = {p for p in _descendants(os.getpid()) - before if _alive(p)}
    assert not left, f"processes left: {left}"
    with pytest.raises(OSError):
        urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=2)
