"""Recording with rosbags, recovering a killed recording, offline measurement of a bag equal to the live
node's, and the drag node on synthetic instrument streams."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from helpers import run_cli
from ros_harness import run_scenario
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from veg_area_ros.bags import typestore
from veg_area_ros.cdr import decode_image
from veg_area_ros.sim.synthetic import scene_targets_content

pytestmark = pytest.mark.timeout(400)


def store_of(reader: Reader):
    """The Kilted types and what the bag itself defines (its MCAP schemas), as any rosbags user reads a bag
    without our packages: veg_area_msgs/ProjectedArea must come from the bag alone."""
    store = get_typestore(Stores.ROS2_KILTED)
    for connection in reader.connections:
        if connection.msgtype not in store.types:
            assert connection.msgdef.format.name == "MSG" and connection.msgdef.data, connection
            store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
    return store


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("record")
    result = run_scenario("record", folder, rate_hz=5.0, settle_s=5.0, seconds=10.0)
    return folder, result


def test_recorded_bag_is_complete_and_valid(recorded):
    folder, result = recorded
    assert result["closed_exit"] == 0 and result["killed_exit"] == -9
    metadata = yaml.safe_load((folder / "closed_bag" / "metadata.yaml").read_text())
    info = metadata["rosbag2_bagfile_information"]
    assert info["storage_identifier"] == "mcap" and info["message_count"] > 0
    assert {t["topic_metadata"]["name"] for t in info["topics_with_message_count"]} == {
        "/image_raw", "/camera_info", "/projected_area", "/projected_area/info"}
    counts: dict[str, int] = {}
    with Reader(folder / "closed_bag") as reader:
        assert {c.topic: c.msgtype for c in reader.connections}["/projected_area"] == "veg_area_msgs/msg/ProjectedArea"
        store = store_of(reader)
        for connection, _, data in reader.messages():
            message = store.deserialize_cdr(data, connection.msgtype)  # every message intact
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
            if connection.msgtype == "sensor_msgs/msg/Image":
                ours = decode_image(data)
                assert (ours.width, ours.height, ours.encoding) == (message.width, message.height, "bgr8")
                assert np.array_equal(ours.pixels().ravel(), message.data)
        assert counts == {c.topic: c.msgcount for c in reader.connections}
    assert counts["/image_raw"] >= 20 and counts["/projected_area"] >= 15


def test_the_live_recording_is_mcap_as_ros2_bag_record_writes_it(recorded):
    """Read by the `mcap` library with CRC validation: zstd chunks, and each message's publish time the sender's
    (rclpy's source timestamp, at or before the recorder received it, within a second) where log time is the
    receive time."""
    from mcap.reader import make_reader

    folder, _ = recorded
    with next((folder / "closed_bag").glob("*.mcap")).open("rb") as file:
        reader = make_reader(file, validate_crcs=True)
        assert {c.compression for c in reader.get_summary().chunk_indexes} == {"zstd"}
        delays = [m.log_time - m.publish_time for _, _, m in reader.iter_messages()]
    assert len(delays) > 20 and all(0 <= d < 1e9 for d in delays), (min(delays), max(delays))
    assert sum(d > 0 for d in delays) > 0.9 * len(delays)  # two clocks read at two moments, not one time twice


def test_frames_the_area_node_skipped_are_counted(recorded):
    """camera_node publishes camera_info with every frame: every frame recorded from the area node's first to
    its last is taken by it, counted skipped, or counted lost in transport."""
    folder, _ = recorded
    image_stamps, infos = [], []
    store = get_typestore(Stores.ROS2_KILTED)
    with Reader(folder / "closed_bag") as reader:
        for connection, _, data in reader.messages():
            if connection.topic == "/image_raw":
                header = decode_image(data).header
                image_stamps.append((header.sec, header.nanosec))
            elif connection.topic == "/projected_area/info":
                infos.append(json.loads(store.deserialize_cdr(data, connection.msgtype).data))
    # from the first result after the bag's first image (a recorder finds a new publisher by polling, so it
    # may join a topic after the area node did) to the last: every image in between is taken or counted skipped
    def stamp(info: dict) -> tuple[int, int]:
        return info["stamp"]["sec"], info["stamp"]["nanosec"]
    seen = [(stamp(i), i["frames_received"], i["frames_measured"], i["frames_dropped"]) for i in infos]
    first = next((i for i in infos if stamp(i) > image_stamps[0] and i["frames_dropped"] is not None), None)
    assert first is not None, (image_stamps[:3], seen)
    last = infos[-1]
    counted = {k: (last[k] or 0) - (first[k] or 0)
               for k in ("frames_received", "frames_measured", "frames_dropped", "frames_lost")}
    # none refused in the window (a frame that beat the latched calibration to a starting node is not measured)
    assert counted["frames_measured"] == counted["frames_received"], seen
    span = [s for s in image_stamps if stamp(first) < s <= stamp(last)]
    assert len(span) >= 20
    # a frame the transport lost on a loaded machine is counted too, as lost rather than skipped
    total = counted["frames_received"] + counted["frames_dropped"] + counted["frames_lost"]
    assert total == len(span), (counted, len(span), image_stamps, seen)


def test_the_bag_keeps_each_topics_offered_qos_and_the_distro(recorded):
    """As rosbag2 writes them: `ros2 bag play` re-latches camera_info only if the bag says it was latched."""
    folder, _ = recorded
    info = yaml.safe_load((folder / "closed_bag" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["ros_distro"] == "kilted"
    offered = {t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"]
               for t in info["topics_with_message_count"]}
    assert [q["durability"] for q in offered["/camera_info"]] == ["transient_local"]
    assert [q["reliability"] for q in offered["/image_raw"]] == ["best_effort"]
    assert all(q["reliability"] == "reliable" for q in offered["/projected_area"])


def test_a_replayed_bag_is_measured_as_live(recorded, tmp_path):
    """`veg-area play` of the recorded camera (image_raw, latched camera_info) to a fresh area node: Af of every
    replayed frame equals the live node's, within the live run's std (exact where both started alike)."""
    folder, _ = recorded
    result = run_scenario("replay", tmp_path, bag=str(folder / "closed_bag"))
    assert result["player_exit"] == 0 and result["area_alive"], result
    store = typestore()  # ProjectedArea registered from veg_area_msgs's installed .msg file
    live, live_std = {}, {}
    with Reader(folder / "closed_bag") as reader:
        wanted = [c for c in reader.connections if c.topic == "/projected_area"]
        for connection, _, data in reader.messages(connections=wanted):
            message = store.deserialize_cdr(data, connection.msgtype)
            key = f"{message.header.stamp.sec}.{message.header.stamp.nanosec:09d}"
            live[key], live_std[key] = message.area_m2, message.area_std_m2
    replayed = result["areas"]
    common = set(live) & set(replayed)
    assert len(live) >= 15 and len(common) >= 0.9 * len(live), (len(live), len(replayed), len(common))
    for key in common:
        assert abs(replayed[key] - live[key]) <= live_std[key], key


def test_record_command_duration_all_and_a_mistyped_topic(tmp_path):
    result = run_scenario("record_cli", tmp_path)
    mistyped, everything = result["mistyped"], result["all"]
    assert mistyped["exit"] == 1 and "never seen on the graph, not recorded: /image_rwa" in mistyped["stderr"]
    assert everything["exit"] == 0, everything["stderr"]
    assert everything["seconds"] < 40  # --duration 8 stopped it (start-up aside)
    info = yaml.safe_load((Path(everything["bag"]) / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    topics = {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
    assert "/image_raw" in topics and "/rosout" not in topics, (topics, everything["stderr"])
    # discovery takes seconds: the recorder says what it missed of the 5 Hz camera before its first frame
    said = re.search(r"/image_raw: not recorded in the first ([\d.]+) s after the command, about (\d+) messages",
                     everything["stderr"])
    assert said, (topics, everything["stderr"])
    gap, missed = float(said.group(1)), int(said.group(2))
    # the estimate is the gap times the camera's rate as the bag shows it (a loaded machine may run the 5 Hz
    # camera slower): the frames stamped within the first recorded second
    with Reader(everything["bag"]) as reader:
        images = [c for c in reader.connections if c.topic == "/image_raw"]
        stamps = [decode_image(data).header.nanoseconds for _, _, data in reader.messages(connections=images)]
    rate = sum(1 for s in stamps if s - stamps[0] <= 1_000_000_000) - 1
    # the recording runs until the duration's end, however late discovery found the camera: the 8 s timer starts
    # after the command, so at least 8 s - gap remain after the first frame (2 s allowed for a slow camera)
    assert (stamps[-1] - stamps[0]) / 1e9 >= 8 - gap - 2, (gap, len(stamps), (stamps[-1] - stamps[0]) / 1e9)
    assert 0 < gap < 30 and 0 < rate <= 6 and abs(missed - gap * rate) <= 1, (gap, missed, rate)

    # a disk that fills while recording (512 kB, one image is 900 kB): a Traceback and exit 1 before; now the
    # error says what happened and how to get what reached the disk, once, and the exit is 1
    full = result["full"]
    if full is None:
        pytest.skip("unshare is not installed: no private mount namespace for a full disk")
    assert full["exit"] == 1, full["stderr"]
    assert "Traceback" not in full["stderr"], full["stderr"]
    assert full["stderr"].count("could not be written (No space left on device, a full disk?)") == 1, full["stderr"]
    assert "veg-area bag-recover" in full["stderr"], full["stderr"]
    assert "QoS did not match" not in full["stderr"], full["stderr"]


def test_killed_recording_is_recovered_but_for_the_last_chunk(recorded, tmp_path):
    folder, _ = recorded
    with pytest.raises(Exception):  # noqa: B017 - rosbags' error for a bag without metadata
        Reader(folder / "killed_bag").open()
    done = run_cli("bag-recover", str(folder / "killed_bag"), str(tmp_path / "recovered"))
    assert done.returncode == 0, done.stderr
    with Reader(tmp_path / "recovered") as reader:
        images = [decode_image(data) for _, _, data in reader.messages()]
    # each chunk is ~1 MB: at most the one 640x480 frame being filled (0.9 MB) plus one more is lost
    mcap = next((folder / "killed_bag").glob("*.mcap"))
    assert len(images) >= 10 and len(images) * 921_600 >= mcap.stat().st_size - 2 * 1_050_000
    assert all(image.pixels().shape == (480, 640, 3) for image in images)


def test_offline_results_equal_the_live_nodes_frame_by_frame(recorded, tmp_path):
    folder, _ = recorded
    targets = tmp_path / "targets.yaml"
    targets.write_text(yaml.safe_dump(scene_targets_content()))
    live, live_std, live_info, first_frames = {}, {}, {}, []
    with Reader(folder / "closed_bag") as reader:
        store = store_of(reader)
        wanted = [c for c in reader.connections if c.topic in ("/projected_area", "/projected_area/info")]
        for connection, _, data in reader.messages(connections=wanted):
            message = store.deserialize_cdr(data, connection.msgtype)
            if connection.topic == "/projected_area/info":
                info = json.loads(message.data)
                if info["frames_received"] == 1:
                    first_frames.append((info["stamp"]["sec"], info["stamp"]["nanosec"]))
                live_info[(info["stamp"]["sec"], info["stamp"]["nanosec"])] = info
                continue
            live[(message.header.stamp.sec, message.header.stamp.nanosec)] = message.area_m2
            live_std[(message.header.stamp.sec, message.header.stamp.nanosec)] = message.area_std_m2
    # from the live node's first frame on (the bag starts earlier): the pixel weights are carried from frame to
    # frame, so the same first frame gives the same numbers
    first = min(live)
    done = run_cli("measure", str(folder / "closed_bag"), "--calibration", "bag", "--targets", str(targets),
                   "--threshold", "120", "--json", "--csv", str(tmp_path / "bag.csv"),
                   "--start-time", f"unix:{first[0] + first[1] * 1e-9 - 1e-6!r}")
    assert done.returncode == 0, done.stderr
    offline = {(r["stamp_sec"], r["stamp_nanosec"]): r for r in map(json.loads, done.stdout.splitlines())
               if "area_m2" in r}
    common = set(live) & set(offline)
    assert len(common) >= 0.8 * len(live) and len(live) >= 15
    # Identical where both measured the same frames from the same first one: tracked markers, weights and light
    # are carried from frame to frame (also across the live node's rebuild when camera_info/metadata comes after
    # its first frames: AreaMeasurer.carry_on_from). The live node's info says how many frames it took and
    # whether it skipped or lost any; the recorder may also have missed an image the live node took (best-effort
    # images on a loaded machine), so the offline run's frames up to a stamp must be as many and all among the
    # live node's. Where the sequences differ, the two agree within their weight error bounds (each run's Af is
    # within its bound of a fresh build); if the recorder started after the live node's first results, or missed
    # the info, within the std.
    same_start = first_frames == [first]
    offline_order = sorted(stamp for stamp in offline if stamp >= first)
    checked = {"same": 0, "bounded": 0, "std": 0}
    for stamp in common:
        info = live_info.get(stamp)
        prefix = offline_order[:offline_order.index(stamp) + 1]
        same_sequence = (same_start and info is not None and not (info["frames_dropped"] or info["frames_lost"])
                         and len(prefix) == info["frames_received"] and set(prefix) <= set(live))
        if same_sequence:
            bound, kind = 1e-9, "same"
        elif same_start and info is not None:
            bound = (info["weight_error_bound"] + offline[stamp]["weight_error_bound"]) * live[stamp] + 1e-12
            kind = "bounded"
        else:
            bound, kind = live_std[stamp], "std"
        checked[kind] += 1
        assert abs(offline[stamp]["area_m2"] - live[stamp]) <= bound, (stamp, kind, checked)
    assert (tmp_path / "bag.png").exists()


def test_drag_node_recovers_a_known_drag_coefficient(tmp_path):
    result = run_scenario("drag", tmp_path, cd=1.05, area_m2=0.0105, velocity_m_s=0.3, seconds=4.0)
    received = np.array(result["received"])
    answered = {tuple(stamp) for stamp in result["received_stamps"]}
    unanswered = [k for k, stamp in enumerate(result["area_stamps"]) if tuple(stamp) not in answered]
    assert len(received) >= 30, f"no Cd for Af messages {unanswered} of {len(result['area_stamps'])}"
    cd, cd_std, velocity = received[:, 0], received[:, 1], received[:, 2]
    assert np.all(np.abs(cd / result["true_cd"] - 1) <= 0.005), cd
    assert np.allclose(velocity, 0.3) and np.all(cd_std > 0)
    # each Cd carries its Af message's exact stamp (an exact-time join with projected_area must match)
    sent = {tuple(stamp) for stamp in result["area_stamps"]}
    assert all(tuple(stamp) in sent for stamp in result["received_stamps"]), result["received_stamps"][:5]
    # every field by name: what Cd was computed from, and its Af frame's warnings passed on
    for named in result["named"]:
        assert named["area_m2"] == 0.0105 and named["area_std_m2"] == pytest.approx(0.002 * 0.0105)
        assert named["density_kg_m3"] == 998.2 and named["velocity_m_s"] == pytest.approx(0.3)
        assert named["force_n"] == pytest.approx(0.5 * 998.2 * 0.3**2 * 0.0105 * 1.05, rel=0.005)
        # the samples in the ±0.05 s window (200 Hz force, 50 Hz velocity; a busy node may drop some)
        assert 1 <= named["force_samples"] <= 21 and 1 <= named["velocity_samples"] <= 6, named
    warned = [named["area_warnings"] for named in result["named"] if named["area_warnings"]]
    assert warned and all(w == ["clipped highlights: a test's warning"] for w in warned), warned
    assert 0.3 < len(warned) / len(result["named"]) < 0.7
    # the deprecated Vector3Stamped beside it, once the drag node has seen our subscription: the same Cd, std
    # and U, stamp for stamp
    stamps = [f"{sec}.{nanosec:09d}" for sec, nanosec in result["received_stamps"]]
    assert len(result["vectors"]) >= 5 and set(result["vectors"]) <= set(stamps), len(result["vectors"])
    for stamp, row in zip(stamps, received, strict=True):
        if stamp in result["vectors"]:
            assert result["vectors"][stamp] == list(row)
    # a start-only parameter changed at run time is refused, not accepted and ignored
    assert result["density_change"] is not None, "the drag node's set_parameters service did not answer"
    ok, reason = result["density_change"]
    assert not ok and "read-only" in reason, reason


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_the_recorder_says_when_it_cannot_keep_a_killed_recording(tmp_path, storage):
    """Crash safety needs rosbags' storage internals (MCAP chunks and file, a sqlite connection): present, each
    chunk reaches the file as it is written; renamed in another rosbags, the recorder says so instead of
    silently writing a bag that a kill would empty."""
    from veg_area_ros.bags import BagRecorder

    recorder = BagRecorder(tmp_path / "bag", storage)
    assert recorder.crash_safety_problem is None
    recorder.add_topic("/chatter", "std_msgs/msg/String")
    recorder.write("/chatter", 1, bytes(8))
    recorder.close()

    class Opaque:  # a storage whose internals were renamed
        def __init__(self, inner):
            self.inner = inner

        def __getattr__(self, name):
            if name in ("chunks", "bio", "conn"):
                raise AttributeError(name)
            return getattr(self.inner, name)

    renamed = BagRecorder(tmp_path / "renamed", storage)
    renamed._writer.storage = Opaque(renamed._writer.storage)
    renamed.crash_safety_problem = renamed._check_crash_safety()
    assert "a recording that is killed loses" in renamed.crash_safety_problem
    renamed.add_topic("/chatter", "std_msgs/msg/String")
    renamed.write("/chatter", 1, bytes(8))  # still records
    assert renamed.counts["/chatter"] == 1
