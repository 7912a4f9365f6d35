"""The ``video`` dataset kind: real KITTI 07 frames written as a video with PyAV and read back
(times, camera, ground truth, pixels), frames decoded in any order and in other processes,
dropped frames, a video re-written with its own codec, and the errors for bad input."""

from __future__ import annotations

import json
import multiprocessing
import pickle
import subprocess
import sys
from dataclasses import replace
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pytest

from sal_adapters import DatasetError, DatasetWarning, Sequence, open_dataset, video_frames, write_sequence
from sal_modules import perturb
from sal_modules.transport.frame_drop import FrameDrop

KITTI_FRAMES = 30
SAL = Path(sys.executable).with_name("sal")


@pytest.fixture(scope="module")
def kitti30(shared_data: Path) -> Sequence:
    return open_dataset("kitti", shared_data / "kitti" / "sequences" / "07", max_frames=KITTI_FRAMES)


@pytest.fixture(scope="module")
def kitti_video(kitti30: Sequence, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The first 30 KITTI 07 frames as ``kitti07.mp4`` (near-lossless), with its sidecars."""
    return write_sequence(kitti30, tmp_path_factory.mktemp("video") / "kitti07.mp4")


@pytest.fixture
def clip(kitti_video: Path, tmp_path: Path) -> Path:
    """``clip.mp4``: the KITTI video under another name, with no sidecar beside it."""
    link = tmp_path / "clip.mp4"
    link.symlink_to(kitti_video)
    return link


@pytest.fixture(autouse=True)
def fresh_decoders() -> None:
    """Each test starts with no open decoder, as a new process would."""
    video_frames._DECODERS.open.clear()


def make_video(path: Path, codec: str = "libx264", frames: int = 40, size: tuple[int, int] = (128, 96), **options: str) -> list[int]:
    """A moving colour pattern as a video of ``codec`` at 25 Hz with a gap after frame 9
    (three frames missing); returns the pts written (1/25 s)."""
    width, height = size
    y, x = np.mgrid[0:height, 0:width]
    written = [i if i < 10 else i + 3 for i in range(frames)]
    with av.open(str(path), "w") as container:
        stream = container.add_stream(codec, rate=25)
        stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
        stream.codec_context.gop_size = 8
        stream.codec_context.options = options
        for pts in written:
            image = np.stack([(x * 2 + pts * 5) % 256, (y * 3 + pts * 7) % 256, (x + y + pts * 11) % 256], axis=2).astype(np.uint8)
            picture = av.VideoFrame.from_ndarray(image, format="rgb24")
            picture.pts = pts
            picture.time_base = Fraction(1, 25)
            container.mux(stream.encode(picture))
        container.mux(stream.encode(None))
    return written


# -- round trips -----------------------------------------------------------------------------
def test_kitti_excerpt_round_trips_through_a_video(kitti30: Sequence, kitti_video: Path) -> None:
    assert sorted(p.name for p in kitti_video.parent.iterdir()) == ["kitti07.groundtruth.txt", "kitti07.mp4", "kitti07.yaml"]
    back = open_dataset("video", kitti_video)
    assert back.kind == "video" and back.name == "video/kitti07" and back.sensor == "mono"
    assert len(back) == KITTI_FRAMES and back.grayscale
    assert np.abs(back.timestamps - kitti30.timestamps).max() <= 1e-6
    assert (back.camera.fx, back.camera.fy, back.camera.cx, back.camera.cy) == (707.0912, 707.0912, 601.8873, 183.1104)
    assert back.camera == kitti30.camera and back.fps == kitti30.fps
    assert back.meta["codec"] == "h264" and back.meta["time_base"] == "1/1000000"
    gt, clean_gt = back.groundtruth, kitti30.groundtruth
    assert gt is not None and clean_gt is not None and back.groundtruth_is_per_frame
    np.testing.assert_array_equal(gt.timestamps, clean_gt.timestamps)
    np.testing.assert_allclose(gt.matrices, clean_gt.matrices, rtol=0, atol=1e-9)
    # grey frames go through x264's lossless mode in full-range gray: measured error 0
    for frame, clean in zip(back, kitti30):
        np.testing.assert_array_equal(frame.image, clean.image)


def test_colour_frames_come_back_within_the_yuv_rounding(shared_data: Path, tmp_path: Path) -> None:
    folder = shared_data / "tum_rgbd_samples" / "fr3_long_office_household_4frames_pyslam"
    clean = open_dataset("folder", folder, intrinsics=(535.4, 539.2, 320.1, 247.6))
    back = open_dataset("video", write_sequence(clean, tmp_path / "fr3.mp4"))
    assert not back.grayscale and back.meta["pix_fmt"] == "yuv444p"
    errors = np.stack([np.abs(a.image.astype(int) - b.image) for a, b in zip(back, clean)])
    # measured on these four TUM frames: max 2, mean 0.38 grey levels (RGB -> limited-range YUV -> RGB)
    assert errors.max() <= 2 and errors.mean() <= 0.5
    np.testing.assert_array_equal(back.timestamps, clean.timestamps)


@pytest.mark.parametrize(("suffix", "tolerance_s"), [(".mov", 1e-6), (".mkv", 0.5e-3), (".avi", 0.104 / 2)])
def test_other_containers_keep_the_frames_and_times_to_their_tick(
    kitti30: Sequence, tmp_path: Path, suffix: str, tolerance_s: float
) -> None:
    clean = perturb(kitti30.select(range(12)), FrameDrop(mode="periodic", period=3), seed=0)
    back = open_dataset("video", write_sequence(clean, tmp_path / f"k{suffix}"))
    assert len(back) == len(clean) == 8
    assert np.abs(back.timestamps - clean.timestamps).max() <= tolerance_s
    for frame, source in zip(back, clean):
        np.testing.assert_array_equal(frame.image, source.image)


def test_a_euroc_clock_survives_through_time_offset(shared_data: Path, tmp_path: Path) -> None:
    clean = open_dataset("euroc", shared_data / "euroc" / "V1_01_easy_micro", max_frames=6)
    path = write_sequence(clean, tmp_path / "v1.mp4")
    assert "time_offset_ns: 1403715273262142976" in path.with_suffix(".yaml").read_text()
    back = open_dataset("video", path)
    assert back.records[0].time_ns == clean.records[0].time_ns  # exact: the offset is stored in ns
    assert max(abs(a.time_ns - b.time_ns) for a, b in zip(back.records, clean.records)) <= 500  # 1 us ticks
    assert back.camera.distortion == clean.camera.distortion and back.fps == 20.0


def test_dropped_frames_stay_dropped_and_the_kept_keep_their_times(kitti30: Sequence, tmp_path: Path) -> None:
    dropped = perturb(kitti30, FrameDrop(drop_rate=0.3), seed=0)
    assert 0 < len(dropped) < KITTI_FRAMES
    back = open_dataset("video", write_sequence(dropped, tmp_path / "dropped.mp4"))
    assert len(back) == len(dropped)
    assert np.abs(back.timestamps - dropped.timestamps).max() <= 1e-6
    assert back.fps == kitti30.fps  # the nominal rate, from the sidecar: gaps do not lower it
    for frame, source in zip(back, dropped):
        np.testing.assert_array_equal(frame.image, source.image)


def test_a_rewritten_video_keeps_its_codec_pixel_format_and_time_base(tmp_path: Path) -> None:
    written = make_video(tmp_path / "source.mp4", codec="mpeg4")
    source = open_dataset("video", tmp_path / "source.mp4", intrinsics=[100, 100, 64, 48])
    assert source.meta["codec"] == "mpeg4" and source.meta["pix_fmt"] == "yuv420p"
    np.testing.assert_allclose(source.timestamps, np.array(written) / 25 - written[0] / 25, atol=1e-9)
    again = open_dataset("video", write_sequence(source, tmp_path / "again.mp4"))  # intrinsics from its sidecar
    assert (again.meta["codec"], again.meta["pix_fmt"], again.meta["time_base"]) == ("mpeg4", "yuv420p", source.meta["time_base"])
    np.testing.assert_array_equal(again.timestamps, source.timestamps)
    assert again.camera == source.camera and len(again) == len(source)
    # MPEG-4 Part 2 cannot count in us: the encoder is refused before anything is written
    fine = source.replace(meta={**source.meta, "time_base": "1/1000000"})
    with pytest.warns(
        DatasetWarning, match=r"video/source: cannot encode as the source video \(mpeg4 yuv420p: .*\); writing near-lossless"
    ):
        fallback = open_dataset("video", write_sequence(fine, tmp_path / "fallback.mp4"))
    assert (fallback.meta["codec"], fallback.meta["pix_fmt"]) == ("h264", "yuv444p")


def test_nothing_to_write_is_an_error_and_leaves_no_file(kitti30: Sequence, tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match=r"kitti/07\+frame_drop.*: no frames to write"):
        write_sequence(perturb(kitti30, FrameDrop(drop_rate=1.0), seed=0), tmp_path / "empty.mp4")
    assert list(tmp_path.iterdir()) == []


def test_a_stereo_sequence_is_written_as_its_left_images(kitti30: Sequence, tmp_path: Path) -> None:
    left = kitti30.select(range(3))
    stereo = left.replace(sensor="stereo", records=[replace(r, right=lambda: np.zeros((370, 1226, 3), np.uint8)) for r in left.records])
    with pytest.warns(DatasetWarning, match="left images only"):
        path = write_sequence(stereo, tmp_path / "stereo.mp4")
    back = open_dataset("video", path)
    assert back.sensor == "mono" and len(back) == 3
    np.testing.assert_array_equal(back[2].image, left[2].image)


# -- decoding --------------------------------------------------------------------------------
def test_frames_read_in_any_order_are_the_same(kitti_video: Path) -> None:
    sequential = [frame.image for frame in open_dataset("video", kitti_video)]
    video_frames._DECODERS.open.clear()
    np.testing.assert_array_equal(open_dataset("video", kitti_video)[17].image, sequential[17])
    seq = open_dataset("video", kitti_video)
    for position in reversed(range(len(seq))):
        np.testing.assert_array_equal(seq[position].image, sequential[position])
    unpickled = pickle.loads(pickle.dumps(seq))
    video_frames._DECODERS.open.clear()
    np.testing.assert_array_equal(unpickled[5].image, sequential[5])


def test_reading_in_order_seeks_once(kitti_video: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seeks: list[int] = []
    original = video_frames._Decoder._seek
    monkeypatch.setattr(video_frames._Decoder, "_seek", lambda self, want: (seeks.append(want.pts), original(self, want))[1])
    seq = open_dataset("video", kitti_video)
    for frame in seq:
        frame.image
    assert len(seeks) == 1  # each frame decoded once: O(n), though the video has a keyframe a second
    seq[3].image  # a step back seeks to the keyframe before it
    assert len(seeks) == 2


def test_b_frames_come_out_in_presentation_order_wherever_reading_starts(tmp_path: Path) -> None:
    written = make_video(tmp_path / "b.mp4", bf="3")
    with av.open(str(tmp_path / "b.mp4")) as container:
        demuxed = [p.pts for p in container.demux(video=0) if p.size]
    assert demuxed != sorted(demuxed)  # the stream does reorder frames
    seq = open_dataset("video", tmp_path / "b.mp4", intrinsics="100 100 64 48")
    np.testing.assert_allclose(seq.timestamps, (np.array(written) - written[0]) / 25, atol=1e-9)
    sequential = [frame.image for frame in seq]
    assert len({im.tobytes() for im in sequential}) == len(written)  # every frame differs
    for position in [30, 5, 17, 16, 39, 0, *reversed(range(len(seq)))]:
        np.testing.assert_array_equal(seq[position].image, sequential[position])


def _mean_of(item: tuple[Sequence, int]) -> float:
    seq, position = item
    return float(seq[position].image.mean())


def test_a_forked_process_decodes_with_its_own_decoder(kitti_video: Path) -> None:
    seq = open_dataset("video", kitti_video)
    means = [float(seq[p].image.mean()) for p in (4, 20)]  # the parent's decoder is open
    with multiprocessing.get_context("fork").Pool(1) as pool:
        assert pool.map_async(_mean_of, [(seq, 4), (seq, 20)]).get(timeout=60) == means
    assert float(seq[21].image.mean()) > 0  # and the parent's goes on


# -- bad input -------------------------------------------------------------------------------
def _faststart_half(source: Path, target: Path) -> None:
    """The first half of ``source`` remuxed with its index at the start (a cut-off download)."""
    whole = target.with_name("whole.mp4")
    with av.open(str(source)) as src, av.open(str(whole), "w", options={"movflags": "faststart"}) as out:
        template = src.streams.video[0]  # PyAV 12 has add_stream(template=), 14 on add_stream_from_template
        stream = out.add_stream_from_template(template) if hasattr(out, "add_stream_from_template") else out.add_stream(template=template)
        for packet in src.demux(video=0):
            if packet.size:
                packet.stream = stream
                out.mux(packet)
    data = whole.read_bytes()
    target.write_bytes(data[: len(data) // 2])


def _audio_only(path: Path) -> None:
    with av.open(str(path), "w") as out:
        stream = out.add_stream("flac", rate=8000)
        sound = av.AudioFrame.from_ndarray(np.zeros((1, 800), np.int16), format="s16", layout="mono")
        sound.sample_rate, sound.pts = 8000, 0
        out.mux(stream.encode(sound))
        out.mux(stream.encode(None))


@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("text", r"notes\.mp4: not a video file FFmpeg can read"),
        ("cut in half", r"half\.mp4: not a video file FFmpeg can read .* cut-off MP4"),
        ("cut in half, index first", r"half\.mp4: cut off: the file's index lists 30 frames, but only \d+ are in it"),
        ("audio only", r"sound\.mkv: no video stream in the file \(streams: audio\)"),
        ("stream 1", r"clip\.mp4: option stream=1: the file has 1 video stream \(stream=0\.\.0\)"),
        ("folder", r"videos: is a folder; the video dataset opens a video file \(found: clip\.mp4\)"),
    ],
)
def test_a_file_that_is_not_a_usable_video_is_named(case: str, message: str, clip: Path, kitti_video: Path, tmp_path: Path) -> None:
    options: dict[str, object] = {"intrinsics": [700, 700, 600, 180]}
    path = tmp_path / {"text": "notes.mp4", "audio only": "sound.mkv", "folder": "videos"}.get(case, "half.mp4")
    if case == "text":
        path.write_text("not a video\n" * 20)
    elif case == "cut in half":
        data = kitti_video.read_bytes()
        path.write_bytes(data[: len(data) // 2])
    elif case == "cut in half, index first":
        _faststart_half(kitti_video, path)
    elif case == "audio only":
        _audio_only(path)
    elif case == "stream 1":
        path, options["stream"] = clip, 1
    else:
        path.mkdir()
        (path / "clip.mp4").symlink_to(kitti_video)
    with pytest.raises(DatasetError, match=message):
        open_dataset("video", path, **options)


@pytest.mark.parametrize(
    ("sidecar", "message"),
    [
        ("fx: [1, 2]\nfy: 700\ncx: 600\ncy: 180\n", r"clip\.yaml:1: fx: expected a number, got a list"),
        ("fy: 700\ncx: 600\ncy: 180\n", r"clip\.yaml: missing fx \(px\)"),
        ("fx: .nan\nfy: 700\ncx: 600\ncy: 180\n", r"clip\.yaml:1: fx: expected a finite number"),
        ("fx: -5\nfy: 700\ncx: 600\ncy: 180\n", r"clip\.yaml: camera fx must be > 0 px"),
        ("fx: 700\nfy: 700\ncx: 6000\ncy: 180\n", r"clip\.yaml: principal point cx=6000 cy=180 px lies outside the 1226x370 px frame"),
        (
            "fx: 700\nfy: 700\ncx: 600\ncy: 180\nwidth: 640\nheight: 480\n",
            r"clip\.yaml: width x height is 640x480 px but the video is 1226x370",
        ),
        ("fxx: 700\n", r"clip\.yaml:1: unknown key 'fxx'; did you mean 'fx'\?"),
        ("fx: 700\nfy: 700\ncx: 600\ncy: 180\ngrayscale: 1\n", r"clip\.yaml:5: grayscale: expected true or false"),
        (
            "fx: 700\nfy: 700\ncx: 600\ncy: 180\ngroundtruth: gone.txt\n",
            r"clip\.yaml:5: groundtruth: ground-truth file .*gone\.txt not found",
        ),
        ("time_offset_s: 1.5\ntime_offset_ns: 7\n", r"clip\.yaml:2: time_offset_ns: 7 ns differs from time_offset_s"),
    ],
)
def test_a_bad_sidecar_is_named_with_its_key(sidecar: str, message: str, clip: Path) -> None:
    clip.with_suffix(".yaml").write_text(sidecar)
    with pytest.raises(DatasetError, match=message):
        open_dataset("video", clip)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"intrinsics": [700, float("nan"), 600, 180]}, r"clip\.mp4: option intrinsics .* needs 4 finite numbers"),
        ({"intrinsics": [700, 0, 600, 180]}, r"clip\.mp4: camera fy must be > 0 px"),
        ({"intrinsics": [2e6, 700, 600, 180]}, r"clip\.mp4: camera fx must be > 0 px and at most 1e\+06 px"),
        ({"intrinsics": "700 700 600 180", "groundtruth": "gone.txt"}, r"gone\.txt: ground-truth file not found \(option groundtruth\)"),
        ({"camera_yaml": "nowhere.yaml"}, r"nowhere\.yaml: sidecar YAML not found \(option camera_yaml\)"),
        ({"intrinsics": "700 700 600 180", "stream": "0"}, r"clip\.mp4: option stream='0'"),
    ],
)
def test_a_bad_option_is_named(options: dict[str, object], message: str, clip: Path) -> None:
    with pytest.raises(DatasetError, match=message):
        open_dataset("video", clip, **options)


def test_without_intrinsics_the_error_names_the_sidecar_and_the_option(clip: Path) -> None:
    with pytest.raises(DatasetError) as caught:
        open_dataset("video", clip)
    text = str(caught.value)
    assert text.startswith(f"{clip}: no camera intrinsics")
    assert str(clip.with_suffix(".yaml")) in text and "intrinsics=[fx, fy, cx, cy]" in text


def test_orbslam3_settings_give_the_camera(clip: Path, tmp_path: Path) -> None:
    settings = tmp_path / "orb.yaml"
    settings.write_text(
        '%YAML:1.0\nFile.version: "1.0"\nCamera.type: "PinHole"\nCamera1.fx: 701.5\nCamera1.fy: 702.5\n'
        "Camera1.cx: 600.25\nCamera1.cy: 180.75\nCamera1.k1: -0.1\nCamera1.k2: 0.01\nCamera1.p1: 0.0\nCamera1.p2: 0.0\n"
        "Camera.width: 1226\nCamera.height: 370\nCamera.fps: 10\nIMU.T_b_c1: !!opencv-matrix\n  rows: 1\n  cols: 1\n  dt: f\n  data: [1.0]\n"
        "ORBextractor.nFeatures: 2000\n"
    )
    seq = open_dataset("video", clip, camera_yaml=settings)
    assert (seq.camera.fx, seq.camera.fy, seq.camera.cx, seq.camera.cy) == (701.5, 702.5, 600.25, 180.75)
    assert seq.camera.distortion == (-0.1, 0.01, 0.0, 0.0) and seq.fps == 10.0


def test_sal_dataset_info_prints_a_video(kitti_video: Path) -> None:
    done = subprocess.run([str(SAL), "dataset", "info", "video", str(kitti_video), "--json"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    info = json.loads(done.stdout)
    assert info["frames"] == KITTI_FRAMES and info["camera"]["fx"] == 707.0912
    assert info["fps"] == pytest.approx(9.615385) and info["groundtruth_poses"] == KITTI_FRAMES
    done = subprocess.run([str(SAL), "dataset", "info", "video", str(kitti_video)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "  video        h264 yuvj420p, " in done.stdout and "time base 1/1000000 s" in done.stdout
    assert f"  sidecar      {kitti_video.with_suffix('.yaml')} (time_offset_s 0.0 s)" in done.stdout


def test_sal_dataset_info_names_a_file_that_is_not_a_video(tmp_path: Path) -> None:
    (tmp_path / "notes.mp4").write_text("not a video\n")
    done = subprocess.run([str(SAL), "dataset", "info", "video", str(tmp_path / "notes.mp4")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and done.stderr.startswith(f"sal: error: {tmp_path / 'notes.mp4'}: not a video file")
