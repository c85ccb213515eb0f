"""ROS 2 interop over Zenoh: ``view --ros2`` publishes PoseArray and MarkerArray in CDR on
rmw_zenoh's keys with its liveliness tokens; a plain Zenoh subscriber on the rmw_zenoh key
decodes them with rosbags (the maintained CDR library) to the synthetic run's robots."""
from __future__ import annotations

import struct
import sys
import time

import pytest

from swarmcover.bus.session import Mailbox
from procs import client_session, free_port
from swarmcover.ros2 import (MARKER_ARRAY, POSE_ARRAY, data_key, deserialize, dds_type,
                             marker_array, pose_array, serialize, type_hash)
from swarmcover.viz.synth import Scenario

SYNTH = [sys.executable, "-m", "swarmcover.viz.synth"]
CYCLES, KILL = 8, (5, 2)


def test_builders_round_trip_through_rosbags_cdr():
    sc = Scenario()
    truth, cx = sc.truth(12, 0.5, 3, 0.2), sc.complex(12, 0.2)
    pa = deserialize(serialize(pose_array(truth, 1_500_000_000), POSE_ARRAY), POSE_ARRAY)
    assert pa.header.frame_id == "map" and pa.header.stamp.sec == 1
    assert [(p.position.x, p.position.y) for p in pa.poses] == list(zip(truth.x, truth.y))
    ma = deserialize(serialize(marker_array(sc.info, truth, cx, {}, 5), MARKER_ARRAY),
                     MARKER_ARRAY)
    ns = {mk.ns for mk in ma.markers}
    assert {"walls", "sources", "ids", "edges"} <= ns
    assert ma.markers[0].action == 3  # DELETEALL first: each array replaces the last
    texts = sorted(int(mk.text) for mk in ma.markers if mk.ns == "ids")
    assert texts == sorted(truth.ids)
    assert dds_type(POSE_ARRAY) == "geometry_msgs::msg::dds_::PoseArray_"
    # REP-2011 hash as rosbags computes it (the value ROS 2 Jazzy ships for PoseArray)
    assert type_hash(POSE_ARRAY) == ("RIHS01_af0cc36d190e104d546d168d6b39df04fa4b4ccecf59cb4"
                                     "c9ed328d3d5004aa0")


def test_view_ros2_publishes_on_rmw_zenoh_keys_with_graph_tokens(router, zargs, procs):
    synth = procs.start(SYNTH + ["--cycles", str(CYCLES), "--cycle-s", "0.15", "--hold", "60",
                                 "--kill", f"{KILL[0]}:{KILL[1]}", *zargs])
    synth.wait_line("READY synth", timeout=30)
    expected = Scenario(kills={KILL[0]: [KILL[1]]}).present(CYCLES - 1)
    s = client_session(router, "ros2test")
    poses_mb, markers_mb = Mailbox(), Mailbox()
    atts = []

    def on_poses(sample):
        atts.append(None if sample.attachment is None else sample.attachment.to_bytes())
        poses_mb.callback(sample)

    subs = [s.declare_subscriber(data_key("/swarmcover/poses", POSE_ARRAY), on_poses),
            s.declare_subscriber(data_key("/swarmcover/complex", MARKER_ARRAY),
                                 markers_mb.callback)]
    try:
        view = procs.swarmcover("view", "--port", free_port(), "--ros2", *zargs)
        line = view.wait_line("READY ros2", timeout=30)
        assert line.split()[2:] == ["/swarmcover/poses", "/swarmcover/complex"]
        ok_poses = ok_markers = False
        deadline = time.monotonic() + 40
        while time.monotonic() < deadline and not (ok_poses and ok_markers):
            for _, payload, _ in poses_mb.drain():
                pa = deserialize(payload, POSE_ARRAY)
                ok_poses = ok_poses or len(pa.poses) == len(expected)
            for _, payload, _ in markers_mb.drain():
                ma = deserialize(payload, MARKER_ARRAY)
                ids = sorted(int(mk.text) for mk in ma.markers if mk.ns == "ids")
                ok_markers = ok_markers or ids == expected
            time.sleep(0.1)
        assert ok_poses and ok_markers, view.output()[-2000:]
        # rmw_zenoh's attachment: int64 sequence number, int64 source timestamp, 16-byte gid
        att = atts[-1]
        assert att is not None and len(att) == 8 + 8 + 1 + 16
        seq, stamp = struct.unpack_from("<qq", att)
        assert seq >= 1 and abs(stamp / 1e9 - time.time()) < 60
        # the ROS graph: a node token and one MP token per topic, as rmw_zenoh declares them
        tokens = [str(r.ok.key_expr) for r in s.liveliness().get("@ros2_lv/0/**", timeout=3)
                  if r.ok]
        nodes = [t for t in tokens if "/NN/" in t]
        pubs = [t for t in tokens if "/MP/" in t]
        assert len(nodes) == 1 and nodes[0].endswith("/%/%swarmcover/swarmcover_view")
        assert any(t.endswith(f"/%swarmcover%poses/{dds_type(POSE_ARRAY)}/"
                              f"{type_hash(POSE_ARRAY)}/::,:,:,:,,") for t in pubs), pubs
        assert any(f"/%swarmcover%complex/{dds_type(MARKER_ARRAY)}/" in t for t in pubs), pubs
    finally:
        for sub in subs:
            sub.undeclare()
        s.close()


def test_bad_ros_namespace_is_a_clear_error(router, procs):
    p = procs.swarmcover("view", "--port", free_port(), "--ros2", "--ros-namespace", "bad",
                         "--connect", router)
    assert p.wait(30) == 2
    assert "--ros-namespace 'bad'" in p.output() and "Traceback" not in p.output()


def test_hwbridge_twist_is_rosbags_cdr_byte_for_byte():
    from swarmcover.hwbridge.ros2 import CDR_LE, Twist, encode_twist
    data = encode_twist(Twist(lx=0.3, az=-1.2))
    tw = deserialize(data, "geometry_msgs/msg/Twist")
    assert (tw.linear.x, tw.angular.z) == (0.3, -1.2)
    assert data == CDR_LE + struct.pack("<6d", 0.3, 0, 0, 0, 0, -1.2)  # the wire is unchanged
    with pytest.raises(ValueError, match="non-finite"):
        encode_twist(Twist(lx=float("nan")))
