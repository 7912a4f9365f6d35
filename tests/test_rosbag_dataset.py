"""The ``rosbag`` dataset kind (issue 26): the KITTI 07 and EuRoC V1_01 excerpts as ROS 1, ROS 2
sqlite3, ROS 2 MCAP and bare MCAP bags read back equal to the folder adapters; perturbed bags
written back with every other topic intact; compressed images, depth, TF chains and Odometry
from hand-made bags; and the bad inputs, each one error naming the bag and the topic."""

from __future__ import annotations

import pickle
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from rosbag_files import CAMERA, TYPES, camera_bag, frame_pixels, image, info, jpeg, make_bags, pose_at, pose_message, tf, write_ros2_bag
from rosbags.highlevel import AnyReader

from sal_adapters import DatasetError, DatasetWarning, Sequence, open_dataset, write_sequence
from sal_adapters.rosbag.messages import header
from sal_adapters.trajectory import Trajectory
from sal_modules import perturb
from sal_modules.light.night import Night
from sal_modules.transport.frame_drop import FrameDrop

KITTI_FRAMES = 20
STEREO = {"image_topic": "/cam0/image_raw", "right_image_topic": "/cam1/image_raw"}


@pytest.fixture(scope="module")
def kitti(shared_data: Path) -> Sequence:
    return open_dataset("kitti", shared_data / "kitti", sequence="07", max_frames=KITTI_FRAMES)


@pytest.fixture(scope="module")
def kitti_bags(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    return make_bags("kitti", shared_data / "kitti", tmp_path_factory.mktemp("bags"), "sequence=07", f"max_frames={KITTI_FRAMES}")


@pytest.fixture(scope="module")
def euroc(shared_data: Path) -> Sequence:
    with pytest.warns(DatasetWarning, match="rows skipped"):  # the excerpt lacks 4 cam1 images
        return open_dataset("euroc", shared_data / "euroc" / "V1_01_easy_micro", stereo=True, max_frames=30)


@pytest.fixture(scope="module")
def euroc_bags(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    return make_bags("euroc", shared_data / "euroc" / "V1_01_easy_micro", tmp_path_factory.mktemp("bags"), "stereo=true", "max_frames=30")


def counts(path: Path) -> Counter[str]:
    """Messages per topic, as rosbags' own reader counts them."""
    with AnyReader([path]) as reader:
        return Counter(connection.topic for connection, _, _ in reader.messages())


def assert_same_frames(a: Sequence, b: Sequence, right: bool = False) -> None:
    assert len(a) == len(b)
    assert [r.time_ns for r in a.records] == [r.time_ns for r in b.records]
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.image, y.image)
        if right:
            np.testing.assert_array_equal(x.right, y.right)


# -- reading the real excerpts ---------------------------------------------------------------
@pytest.mark.parametrize("which", range(4), ids=["ros1", "sqlite3", "mcap", "mcap_file"])
def test_kitti07_bag_reads_like_the_folder(which: int, kitti: Sequence, kitti_bags: list[Path]) -> None:
    seq = open_dataset("rosbag", kitti_bags[which])
    assert (seq.kind, seq.sensor, seq.grayscale) == ("rosbag", "mono", True)
    assert_same_frames(seq, kitti)  # pixels to the bit, stamps to the ns
    np.testing.assert_allclose(seq.timestamps, kitti.timestamps, rtol=0, atol=1e-9)
    assert (seq.camera.fx, seq.camera.fy, seq.camera.cx, seq.camera.cy) == (707.0912, 707.0912, 601.8873, 183.1104)
    assert (seq.camera.width, seq.camera.height) == (kitti.camera.width, kitti.camera.height)
    assert seq.fps == pytest.approx(kitti.fps, rel=0.01)  # the median step of 20 frames (KITTI: the mean)
    assert seq.groundtruth is not None and kitti.groundtruth is not None
    assert seq.groundtruth_is_per_frame and seq.groundtruth.allclose(kitti.groundtruth, atol=1e-9)


@pytest.mark.parametrize("which", [0, 2], ids=["ros1", "mcap"])
def test_euroc_stereo_bag_reads_like_the_folder(which: int, euroc: Sequence, euroc_bags: list[Path]) -> None:
    seq = open_dataset("rosbag", euroc_bags[which], **STEREO)
    assert seq.sensor == "stereo"
    assert_same_frames(seq, euroc, right=True)
    np.testing.assert_allclose(seq.camera.T_lr, euroc.camera.T_lr, atol=1e-12)  # from /tf_static cam0 -> cam1
    assert seq.camera.right is not None and euroc.camera.right is not None
    assert seq.camera.right.fx == euroc.camera.right.fx and seq.camera.distortion == euroc.camera.distortion
    assert seq.groundtruth is not None and euroc.groundtruth is not None
    assert seq.groundtruth.allclose(euroc.groundtruth, atol=1e-9)


def test_a_sequence_pickles_and_decodes_its_frames_lazily(kitti: Sequence, kitti_bags: list[Path]) -> None:
    seq = pickle.loads(pickle.dumps(open_dataset("rosbag", kitti_bags[3])))
    np.testing.assert_array_equal(seq[KITTI_FRAMES - 1].image, kitti[KITTI_FRAMES - 1].image)
    assert seq.fingerprint == open_dataset("rosbag", kitti_bags[3]).fingerprint
    assert open_dataset("rosbag", kitti_bags[3], max_frames=5).fingerprint != seq.fingerprint


# -- writing back ------------------------------------------------------------------------------
@pytest.mark.parametrize(("which", "target"), [(0, "out.bag"), (3, "out.mcap"), (1, "folder")], ids=["ros1", "mcap_file", "sqlite3"])
def test_a_perturbed_bag_keeps_every_other_topic_and_loses_only_dropped_frames(
    which: int, target: str, kitti_bags: list[Path], tmp_path: Path
) -> None:
    source = kitti_bags[which]
    clean = open_dataset("rosbag", source)
    perturbed = perturb(clean, [Night(illuminance_lux=20), FrameDrop(drop_rate=0.3)], seed=3)
    assert 0 < len(perturbed) < len(clean)
    out = write_sequence(perturbed, tmp_path / target)
    before, after = counts(source), counts(out)
    assert after["/cam0/image_raw"] == len(perturbed)
    assert {t: n for t, n in after.items() if t != "/cam0/image_raw"} == {t: n for t, n in before.items() if t != "/cam0/image_raw"}
    back = open_dataset("rosbag", out)
    assert back.meta["format"] == clean.meta["format"] or (target == "out.mcap" and back.meta["format"] == "mcap_file")
    assert_same_frames(back, perturbed)  # the perturbed pixels (mono8, lossless) at the kept frames' stamps
    assert back.camera == clean.camera and back.groundtruth is not None and back.groundtruth.allclose(clean.groundtruth)


def test_read_write_read_of_a_stereo_bag_gives_the_same_frames_stamps_and_calibration(euroc_bags: list[Path], tmp_path: Path) -> None:
    clean = open_dataset("rosbag", euroc_bags[1], **STEREO)
    out = write_sequence(clean, tmp_path / "copy")
    assert counts(out) == counts(euroc_bags[1])  # IMU, TF, CameraInfo and both image topics
    back = open_dataset("rosbag", out, **STEREO)
    assert_same_frames(back, clean, right=True)
    assert back.camera == clean.camera and back.groundtruth is not None and back.groundtruth.allclose(clean.groundtruth)


def test_an_excerpt_is_written_with_the_other_topics_of_its_time_span(euroc_bags: list[Path], tmp_path: Path) -> None:
    excerpt = open_dataset("rosbag", euroc_bags[2], start=5, max_frames=10, **STEREO)
    out = write_sequence(excerpt, tmp_path / "excerpt.mcap")
    found = counts(out)
    assert found["/cam0/image_raw"] == found["/cam1/image_raw"] == 10
    assert 0 < found["/imu0"] < counts(euroc_bags[2])["/imu0"]  # 200 Hz IMU over the 10 frames' 0.45 s
    assert found["/imu0"] == pytest.approx(0.45 * 200, abs=2)


def test_a_bag_is_not_written_back_across_ros_versions(kitti_bags: list[Path], tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match=r"comes from a ROS 1 bag and is written back as one .*: name the output .bag"):
        write_sequence(open_dataset("rosbag", kitti_bags[0]), tmp_path / "out.mcap")
    assert not (tmp_path / "out.mcap").exists()


def test_a_folder_dataset_is_written_as_a_new_bag(kitti: Sequence, tmp_path: Path) -> None:
    out = write_sequence(kitti.select(range(5)), tmp_path / "kitti.bag")
    back = open_dataset("rosbag", out)
    assert_same_frames(back, kitti.select(range(5)))
    assert back.camera.fx == 707.0912 and back.groundtruth is not None and len(back.groundtruth) == 5


def test_an_existing_output_file_and_the_source_bag_are_never_overwritten(kitti_bags: list[Path], tmp_path: Path) -> None:
    clean = open_dataset("rosbag", kitti_bags[3])
    with pytest.raises(DatasetError, match="refusing to write into the source"):
        write_sequence(clean, kitti_bags[3])
    (tmp_path / "taken.mcap").write_bytes(b"a user's recording")
    with pytest.raises(DatasetError, match="output file exists") as error:
        write_sequence(clean, tmp_path / "taken.mcap")
    assert "taken.mcap" in str(error.value) and (tmp_path / "taken.mcap").read_bytes() == b"a user's recording"


# -- encodings, depth, ground truth from hand-made bags ----------------------------------------
def test_compressed_images_decode_close_to_their_pixels_and_are_written_back_compressed(tmp_path: Path) -> None:
    bag = camera_bag(tmp_path / "jpeg", make=lambda number, ns: jpeg(ns, frame_pixels(number)))
    seq = open_dataset("rosbag", bag)
    assert not seq.grayscale and (seq.camera.width, seq.camera.height) == (64, 48)
    error = np.abs(seq[3].image.astype(int) - frame_pixels(3).astype(int))
    assert error.mean() < 3.0  # JPEG quality 98 of a smooth pattern
    out = write_sequence(seq, tmp_path / "out.mcap")
    with AnyReader([out]) as reader:
        kinds = {c.topic: c.msgtype for c in reader.connections}
    assert kinds["/cam/image_raw"] == "sensor_msgs/msg/CompressedImage"
    assert np.abs(open_dataset("rosbag", out)[3].image.astype(int) - seq[3].image.astype(int)).mean() < 3.0


@pytest.mark.parametrize("encoding", ["bgr8", "rgba8", "mono8"])
def test_raw_encodings_become_rgb(encoding: str, tmp_path: Path) -> None:
    rgb = frame_pixels(1)
    pixels = {"bgr8": rgb[..., ::-1], "rgba8": np.concatenate([rgb, np.full((48, 64, 1), 7, np.uint8)], axis=2), "mono8": rgb[..., 0]}[
        encoding
    ]
    seq = open_dataset("rosbag", camera_bag(tmp_path / encoding, frames=2, make=lambda n, ns: image(ns, pixels, encoding)))
    expected = np.repeat(rgb[..., :1], 3, axis=2) if encoding == "mono8" else rgb
    np.testing.assert_array_equal(seq[0].image, expected)
    assert seq.grayscale == (encoding == "mono8")


def test_rgbd_pairs_depth_by_stamp_within_the_tolerance(tmp_path: Path) -> None:
    depth_mm = np.full((48, 64), 1500, np.uint16)
    depth_mm[0, 0] = 0
    extra = [("/depth", "sensor_msgs/msg/Image", ns, image(ns, depth_mm, "16UC1")) for ns in (1_007_000_000, 1_107_000_000, 1_240_000_000)]
    bag = camera_bag(tmp_path / "rgbd", frames=3, extra=extra)
    with pytest.warns(DatasetWarning, match="1 of 3 images on /cam/image_raw have no /depth message within 0.02 s"):
        seq = open_dataset("rosbag", bag, depth_topic="/depth")
    assert seq.sensor == "rgbd" and len(seq) == 2  # the third image's depth is 40 ms off
    assert seq[1].depth is not None and seq[1].depth[1, 1] == pytest.approx(1.5) and seq[1].depth[0, 0] == 0.0
    assert len(open_dataset("rosbag", bag, depth_topic="/depth", pair_tolerance_s=0.05)) == 3


def test_groundtruth_chains_a_moving_tf_with_a_static_one_and_interpolates(tmp_path: Path) -> None:
    mount = np.eye(4)
    mount[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # camera looking along the body's x
    mount[:3, 3] = [0.2, 0.0, 1.1]
    extra = [("/tf_static", "tf2_msgs/msg/TFMessage", 900_000_000, tf(900_000_000, mount, "base_link", "cam"))]
    extra += [
        ("/tf", "tf2_msgs/msg/TFMessage", ns, tf(ns, pose_at(ns * 1e-9), "odom", "base_link"))
        for ns in range(950_000_000, 2_000_000_000, 25_000_000)
    ]
    seq = open_dataset("rosbag", camera_bag(tmp_path / "tf", extra=extra))  # the images' frame_id "cam" finds the chain
    truth = seq.groundtruth
    assert truth is not None and len(truth) == 42
    expected = Trajectory.from_matrices(truth.timestamps, np.array([pose_at(t) @ mount for t in truth.timestamps]))
    assert truth.allclose(expected, atol=1e-9)
    body = open_dataset("rosbag", camera_bag(tmp_path / "tf2", extra=extra), groundtruth_frames=["odom", "base_link"]).groundtruth
    assert body is not None and np.allclose(body.matrices[5], pose_at(body.timestamps[5]))
    with pytest.raises(DatasetError, match="TF has no frame 'map'; did you mean 'cam'|TF has no frame 'map'"):
        open_dataset("rosbag", camera_bag(tmp_path / "tf3", extra=extra), groundtruth_frames=["map", "cam"])


def test_groundtruth_from_odometry_moved_to_the_camera_by_static_tf(tmp_path: Path) -> None:
    mount = np.eye(4)
    mount[:3, 3] = [0.0, 0.1, 0.0]

    def odometry(ns: int) -> object:
        geometry = pose_message(pose_at(ns * 1e-9))
        zero = TYPES["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        return TYPES["nav_msgs/msg/Odometry"](
            header=header(TYPES, ns, "map", False),
            child_frame_id="body",
            pose=TYPES["geometry_msgs/msg/PoseWithCovariance"](pose=geometry, covariance=np.zeros(36)),
            twist=TYPES["geometry_msgs/msg/TwistWithCovariance"](
                twist=TYPES["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=np.zeros(36)
            ),
        )

    extra = [("/tf_static", "tf2_msgs/msg/TFMessage", 900_000_000, tf(900_000_000, mount, "body", "cam"))]
    extra += [("/odom", "nav_msgs/msg/Odometry", ns, odometry(ns)) for ns in range(1_000_000_000, 2_000_000_000, 50_000_000)]
    bag = camera_bag(tmp_path / "odom", extra=extra)
    plain = open_dataset("rosbag", bag).groundtruth  # the bag's only Odometry topic: the body's poses
    moved = open_dataset("rosbag", bag, groundtruth_topic="/odom", groundtruth_frames=["map", "cam"]).groundtruth
    assert plain is not None and moved is not None and len(plain) == 20
    assert np.allclose(plain.matrices[7], pose_at(plain.timestamps[7]))
    assert np.allclose(moved.matrices[7], pose_at(moved.timestamps[7]) @ mount)


# -- bad input ---------------------------------------------------------------------------------
def test_a_file_that_is_not_a_bag_is_named(tmp_path: Path) -> None:
    fake = tmp_path / "notes.bag"
    fake.write_text("not a bag at all\n" * 100)
    with pytest.raises(DatasetError, match="not a ROS bag or it is truncated") as error:
        open_dataset("rosbag", fake)
    assert "notes.bag" in str(error.value)
    other = tmp_path / "notes.txt"
    other.write_text("x")
    with pytest.raises(DatasetError, match="expected a .bag file, a .mcap file or a ROS 2 bag folder"):
        open_dataset("rosbag", other)
    with pytest.raises(DatasetError, match="not a ROS 2 bag folder"):
        open_dataset("rosbag", tmp_path)


@pytest.mark.parametrize("which", [0, 3], ids=["ros1", "mcap_file"])
def test_a_truncated_bag_is_one_error_naming_it(which: int, kitti_bags: list[Path], tmp_path: Path) -> None:
    cut = tmp_path / kitti_bags[which].name
    data = kitti_bags[which].read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(DatasetError) as error:
        seq = open_dataset("rosbag", cut)
        for frame in seq:
            frame.image
    assert cut.name in str(error.value) and "truncated" in str(error.value)


def test_an_unknown_topic_names_the_bag_and_the_closest_topic(kitti_bags: list[Path]) -> None:
    with pytest.raises(
        DatasetError, match=r"image_topic='/cam0/image_rwa': no such topic in the bag; did you mean '/cam0/image_raw'\?"
    ) as error:
        open_dataset("rosbag", kitti_bags[2], image_topic="/cam0/image_rwa")
    assert "kitti_mcap" in str(error.value)
    with pytest.raises(DatasetError, match="holds sensor_msgs/msg/CameraInfo, expected sensor_msgs/msg/Image or"):
        open_dataset("rosbag", kitti_bags[2], image_topic="/cam0/camera_info")
    with pytest.raises(DatasetError, match="no such topic in the bag; its topics of that kind: /cam0/image_raw"):
        open_dataset("rosbag", kitti_bags[2], image_topic="/left")


def test_an_unsupported_encoding_names_the_topic_and_the_encoding(tmp_path: Path) -> None:
    bag = camera_bag(tmp_path / "float", frames=2, make=lambda n, ns: image(ns, np.zeros((48, 64), np.float32), "32FC1"))
    with pytest.raises(DatasetError, match="topic /cam/image_raw: image encoding '32FC1' is not supported; supported: 8-bit"):
        open_dataset("rosbag", bag)


def test_stamps_that_go_back_name_the_topic_and_the_message(tmp_path: Path) -> None:
    stamps = {4: 1_250_000_000}  # message 4 stamped before message 3
    bag = camera_bag(tmp_path / "back", make=lambda n, ns: image(stamps.get(n, ns), frame_pixels(n)))
    with pytest.raises(
        DatasetError, match=r"topic /cam/image_raw: message 4 has header stamp 1.250000000 s, not after message 3's 1.300000000 s"
    ):
        open_dataset("rosbag", bag)
    assert len(open_dataset("rosbag", bag, stamps="log")) == 10


def test_missing_calibration_names_the_options(tmp_path: Path) -> None:
    bag = write_ros2_bag(tmp_path / "nocal", [("/img", "sensor_msgs/msg/Image", ns, image(ns, frame_pixels(0))) for ns in (1, 2, 3)])
    with pytest.raises(
        DatasetError, match=r"has no camera_info topic beside it; pass camera_info_topic= \(the bag's: none\) or intrinsics="
    ):
        open_dataset("rosbag", bag)
    seq = open_dataset("rosbag", bag, intrinsics=[100, 100, 32, 24])
    assert seq.camera == CAMERA and info(1).width == 64
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert seq.groundtruth is None


def test_nan_calibration_and_poses_name_the_topic(tmp_path: Path) -> None:
    nan_camera = info(1)
    nan_camera.k[0] = np.nan
    bag = write_ros2_bag(
        tmp_path / "nan",
        [
            ("/cam/image_raw", "sensor_msgs/msg/Image", 1, image(1, frame_pixels(0))),
            ("/cam/camera_info", "sensor_msgs/msg/CameraInfo", 1, nan_camera),
        ],
    )
    with pytest.raises(DatasetError, match="camera of /cam/image_raw: camera fx must be > 0 px"):
        open_dataset("rosbag", bag)
    broken = np.eye(4)
    broken[0, 3] = np.inf
    extra = [
        ("/tf", "tf2_msgs/msg/TFMessage", ns, tf(ns, broken if ns == 1_300_000_000 else pose_at(ns * 1e-9), "odom", "cam"))
        for ns in range(1_000_000_000, 2_000_000_000, 100_000_000)
    ]
    with pytest.raises(DatasetError, match=r"topic /tf: message 3: a pose with a non-finite position"):
        open_dataset("rosbag", camera_bag(tmp_path / "inf", extra=extra))


def test_an_image_shorter_than_its_size_says_so_when_decoded(tmp_path: Path) -> None:
    def short(number: int, ns: int) -> object:
        message = image(ns, frame_pixels(number))
        return message if number != 2 else type(message)(**{**message.__dict__, "data": message.data[:100]})

    seq = open_dataset("rosbag", camera_bag(tmp_path / "short", frames=4, make=short))
    seq[1].image
    with pytest.raises(DatasetError, match=r"topic /cam/image_raw: an image of 64x48 px rgb8 holds 100 bytes with step 192; expected 9216"):
        seq[2].image


def test_a_write_that_fails_midway_leaves_nothing_behind(kitti_bags: list[Path], tmp_path: Path) -> None:
    clean = open_dataset("rosbag", kitti_bags[3])

    def broken() -> np.ndarray:
        raise OSError(28, "No space left on device")

    records = list(clean.records)
    records[5] = type(records[5])(**{**records[5].__dict__, "image": broken})
    with pytest.raises(OSError, match="No space left on device"):
        write_sequence(clean.replace(records=records), tmp_path / "out.mcap")
    assert list(tmp_path.iterdir()) == []  # no half-written bag, no staging folder


#: A "ROS system" for the command recipe: replays the staged bag with rosbags and writes, per
#: image it receives, the camera pose TF gives at that stamp (what a bag-replaying node sees).
REPLAYING_PROGRAM = """
import sys
from pathlib import Path
from rosbags.highlevel import AnyReader

poses, images = {}, []
with AnyReader([Path(sys.argv[1])]) as reader:
    for connection, stamp, raw in reader.messages():
        message = reader.deserialize(raw, connection.msgtype)
        if connection.topic == "/tf":
            t = message.transforms[0]
            poses[stamp] = (t.transform.translation, t.transform.rotation)
        elif connection.topic == "/cam0/image_raw":
            images.append(stamp)
with open(sys.argv[2], "w") as out:
    for stamp in images:
        p, q = poses[stamp]
        out.write(f"{stamp * 1e-9:.9f} {p.x} {p.y} {p.z} {q.x} {q.y} {q.z} {q.w}\\n")
"""


def test_a_command_system_replays_the_perturbed_bag(kitti_bags: list[Path], tmp_path: Path) -> None:
    import sys

    from sal_wrappers import create

    program = tmp_path / "replay.py"
    program.write_text(REPLAYING_PROGRAM)
    clean = open_dataset("rosbag", kitti_bags[0])
    perturbed = perturb(clean, FrameDrop(drop_rate=0.4), seed=2)
    system = create("command", argv=[sys.executable, str(program), "{sequence}", "{output}"], layout="rosbag", deterministic=True)
    result = system.run(perturbed, tmp_path / "work", timeout=120)
    assert result.ok, result.failure
    assert (tmp_path / "work" / "sequence").is_dir() and list((tmp_path / "work" / "sequence").glob("*.bag"))  # same format as the source
    assert result.trajectory is not None and len(result.trajectory) == len(perturbed) < len(clean)
    np.testing.assert_allclose(result.trajectory.timestamps, perturbed.timestamps, atol=1e-9)
    assert result.trajectory.allclose(clean.groundtruth.select([int(i) for i in perturbed.indices]), atol=1e-9)


def test_groundtruth_from_pose_stamped(tmp_path: Path) -> None:
    def stamped(ns: int) -> object:
        geometry = pose_message(pose_at(ns * 1e-9))
        return TYPES["geometry_msgs/msg/PoseStamped"](header=header(TYPES, ns, "world", False), pose=geometry)

    extra = [("/mocap/pose", "geometry_msgs/msg/PoseStamped", ns, stamped(ns)) for ns in range(1_000_000_000, 2_000_000_000, 10_000_000)]
    truth = open_dataset("rosbag", camera_bag(tmp_path / "mocap", extra=extra)).groundtruth
    assert truth is not None and len(truth) == 100
    assert np.allclose(truth.matrices[42], pose_at(truth.timestamps[42]))


def test_sal_perturb_writes_each_perturbed_bag_in_the_source_format(kitti_bags: list[Path], tmp_path: Path) -> None:
    from pytest_sal.cli.main import main

    config = tmp_path / "bag.yaml"
    config.write_text(
        f"experiment: {{name: bag_night, seed: 1}}\n"
        f"dataset: {{type: rosbag, path: '{kitti_bags[3]}', max_frames: 6}}\n"
        "perturbations: [{name: dusk, type: night, parameters: {illuminance_lux: 30}}]\n"
        f"output: {{base_dir: '{tmp_path / 'out'}'}}\n"
    )
    assert main(["perturb", str(config), "--cache-dir", str(tmp_path / "cache")]) == 0
    (bag,) = (tmp_path / "out" / "bag_night" / "images" / "dusk").glob("*.mcap")
    found = counts(bag)
    assert found["/cam0/image_raw"] == found["/tf"] == found["/cam0/camera_info"] == 6  # other topics over the excerpt's span


def test_a_rectified_stereo_pair_is_placed_by_the_right_camera_info(tmp_path: Path) -> None:
    world = open_dataset("synthetic", scene="urban", frames=3, sensor="stereo", cache_dir=tmp_path / "render")
    bag = write_sequence(world, tmp_path / "urban.mcap")  # the right CameraInfo's P carries Tx = -fx * 0.54 m
    seq = open_dataset("rosbag", bag, **STEREO)
    assert seq.camera.right is None and seq.camera.baseline_m == pytest.approx(world.camera.baseline_m, rel=1e-12)
    np.testing.assert_allclose(seq.camera.T_lr, world.camera.T_lr, atol=1e-12)
    assert_same_frames(seq, world, right=True)
    wider = open_dataset("rosbag", bag, baseline_m=0.6, **STEREO)  # a given baseline wins
    assert wider.camera.baseline_m == 0.6
