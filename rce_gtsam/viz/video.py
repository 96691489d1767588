"""Video for the Rerun viewer: Rerun's ``AssetVideo`` plays H.264 / H.265 / AV1 only.

OpenCV's default ``mp4v`` fourcc (MPEG-4 Part 2) is rejected by the viewer (rerun issue #12834), so any
other codec is transcoded to H.264 with PyAV (``libx264``) into a temporary file first.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from ..errors import InputError

#: Codecs Rerun 0.41 decodes (PyAV codec names).
PLAYABLE_CODECS = ("h264", "hevc", "av1")


def video_codec(path: str | Path) -> str:
    """PyAV name of the first video stream's codec, e.g. 'h264' or 'mpeg4'."""
    import av
    try:
        with av.open(str(path)) as c:
            if not c.streams.video:
                raise InputError(path, "the file has no video stream")
            return c.streams.video[0].codec_context.name
    except av.error.FFmpegError as exc:
        raise InputError(path, f"cannot read the video: {exc}") from None


def transcode_h264(src: str | Path, dst: str | Path, crf: int = 23) -> Path:
    """Re-encode ``src`` as H.264 (yuv420p, same frame rate and size) into ``dst`` (mp4)."""
    import av
    dst = Path(dst)
    with av.open(str(src)) as cin, av.open(str(dst), "w") as cout:
        sin = cin.streams.video[0]
        rate = sin.average_rate or sin.guessed_rate or 30
        sout = cout.add_stream("libx264", rate=rate)
        sout.width = sin.codec_context.width - sin.codec_context.width % 2
        sout.height = sin.codec_context.height - sin.codec_context.height % 2
        sout.pix_fmt = "yuv420p"
        sout.options = {"crf": str(crf), "preset": "veryfast"}
        for frame in cin.decode(sin):
            img = frame.reformat(width=sout.width, height=sout.height, format="yuv420p")
            img.pts = None
            for packet in sout.encode(img):
                cout.mux(packet)
        for packet in sout.encode():
            cout.mux(packet)
    return dst


def playable_video(path: str | Path, workdir: str | Path | None = None) -> Path:
    """``path`` itself when Rerun can play it, else an H.264 copy in ``workdir`` (a temp dir by default)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "video file not found")
    if video_codec(path) in PLAYABLE_CODECS:
        return path
    workdir = Path(workdir) if workdir is not None else Path(tempfile.mkdtemp(prefix="rce_video_"))
    return transcode_h264(path, workdir / (path.stem + "_h264.mp4"))


def first_frame(path: str | Path):
    """(H, W, 3) uint8 RGB first frame of a video, or None if it cannot be decoded."""
    import av
    try:
        with av.open(str(path)) as c:
            for frame in c.decode(video=0):
                return frame.to_ndarray(format="rgb24")
    except (av.error.FFmpegError, OSError):
        return None
    return None
