"""foreground_segmentation: per-camera background subtraction for the body tracker (thesis sec. 2.4).

One node serves a list of cameras. For each camera a
:class:`~hmocap_ros.segmentation.BackgroundModel` (per-pixel single Gaussian after Xu et al.,
shadow and illumination-change suppression, morphological clean-up) learns the empty room
from the first frames, then adapts slowly where there is no foreground; with
``learn_from:=person_masks`` a :class:`~hmocap_ros.segmentation.PersonMaskedBackground` learns
each pixel where the landmark network's person masks leave it free (no empty room needed).

The cameras' frames are grouped into frame sets by stamp and segmented in a worker thread
(:class:`~hmocap_ros.frame_intake.FrameSetIntake`): with ``latest_only`` (live) the newest set
when the node falls behind, so every camera's mask of a stamp comes together and soon, as the
extremity node and the tracker take them; with ``latest_only:=false`` every frame in stamp
order (bag replays that must answer every frame).

Subscriptions:
  ``<camera>/image_raw`` (sensor_msgs/Image rgb8/bgr8/mono8), or with ``image_transport:=compressed``
  ``<camera>/image_raw/compressed`` (sensor_msgs/CompressedImage JPEG/PNG), per camera: ``image_reliability``
  (best effort: any camera driver matches) with a queue of ``queue_depth`` frames
  (:func:`~hmocap_ros.nodes.common.image_qos`).
Publications:
  ``<camera>/foreground`` (sensor_msgs/Image mono8, 0 or 255; the input's stamp and frame_id;
  reliable, keep last ``queue_depth``: :func:`~hmocap_ros.nodes.common.image_output_qos`), and
  ``<camera>/foreground/compressed`` (sensor_msgs/CompressedImage PNG, encoded while subscribed).
  ``/diagnostics`` (diagnostic_msgs/DiagnosticArray, every ``diagnostics_period`` s): frames,
  milliseconds per frame and state (learning or segmenting) per camera.
Services:
  ``~/relearn`` (std_srvs/Trigger): forget the background of every camera and learn it again.
The method, its choices and results: docs/segmentation.md. Parameters: ``--help`` prints them
after this text; defaults in config/foreground_segmentation.yaml.

Frames of the wrong encoding or of a size other than the one learnt are refused with a
logged error; after ``relearn_after_size_errors`` consecutive size errors the camera
relearns at the new size (a camera driver was reconfigured). A mono frame (mono8, mono16)
after a background learnt from colour frames, or a colour frame after a mono background, is
refused too, with an error naming the camera and both encodings: against a background of the
other kind every pixel would come out foreground. Colour encodings mix freely (bgr8 after rgb8
is decoded to the same RGB). ``~/relearn`` learns the background anew from the frames that come
next, whatever their encoding.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from std_srvs.srv import Trigger

from hmocap_ros.frame_intake import FrameSetIntake
from hmocap_ros.frame_sets import PickedSet
from hmocap_ros.io.conversions import ConversionError, encoding_layout, numpy_to_image
from hmocap_ros.io.image_codec import decoded_rgb, image_encoding
from hmocap_ros.io.msg_factory import RclpyFactory, stamp_to_ns
from hmocap_ros.nodes.common import (
    RESULT_QOS,
    create_image_publisher,
    create_image_subscription,
    declare_parameters,
    image_qos,
    image_reliability_param,
    image_transport_param,
    param,
    run_node,
)
from hmocap_ros.segmentation import ForegroundParams, background_models, compile_kernels

NODE_NAME = "foreground_segmentation"


@dataclass(frozen=True)
class ForegroundNodeConfig:
    cameras: list[str] = param(["cam_1", "cam_2", "cam_3", "cam_4"],
                               "Camera names: the node subscribes <camera>/image_raw, publishes <camera>/foreground.")
    queue_depth: int = param(25, "Frames queued per camera while the node is busy (what overflows is dropped); "
                                 "25 holds one second at 25 fps.")
    latest_only: bool = param(True, "Live: when frames come faster than the node segments them, segment the "
                                    "newest frame set and skip the others, so the masks stay recent. false: "
                                    "every frame in stamp order (bag replays that must answer every frame).")
    slop_ms: float = param(5.0, "Largest stamp difference (ms) between the frames of one frame set.")
    max_wait_ms: float = param(100.0, "How long (ms, > 0) a frame set waits for a missing camera before the "
                                      "cameras it has are segmented.")
    image_reliability: str = image_reliability_param()
    image_transport: str = image_transport_param()
    diagnostics_period: float = param(1.0, "Seconds between diagnostics messages (0 = none).")
    relearn_after_size_errors: int = param(25, "Relearn a camera's background after this many consecutive "
                                               "frames of a size other than the learnt one (0 = never).")


def is_colour(encoding: str) -> bool:
    """Whether frames of ``encoding`` carry colour (rgb8, bgra16, ...) rather than grey (mono8,
    mono16, 8UC1); raises ConversionError for an unknown encoding."""
    return encoding_layout(encoding).channels >= 3


class _CameraState:
    def __init__(self, model):
        self.model = model
        self.frames = 0
        self.seconds = 0.0
        self.size_errors = 0
        self.encoding: str | None = None  # of the frames the background is learnt from
        self.relearn_requested = False  # by the service, done by the worker

    def relearn(self) -> None:
        self.model.relearn()
        self.encoding = None
        self.size_errors = 0
        self.relearn_requested = False


class ForegroundSegmentation(Node):
    def __init__(self):
        super().__init__(NODE_NAME)
        self.config = declare_parameters(self, ForegroundNodeConfig)
        self.params = declare_parameters(self, ForegroundParams)
        self.factory = RclpyFactory()
        # Before subscribing: compiling on the first frames with a person would drop frames.
        compile_kernels(self.params)
        models = background_models(self.params, self.config.cameras)
        self.cameras = {name: _CameraState(model) for name, model in zip(self.config.cameras, models)}
        self.mask_pubs = {}
        images_qos = image_qos(self.config.image_reliability, self.config.queue_depth)
        for name in self.cameras:
            self.mask_pubs[name] = create_image_publisher(self, f"{name}/foreground", self.config.queue_depth)
        if self.config.max_wait_ms <= 0:
            raise ValueError(f"max_wait_ms must be > 0, got {self.config.max_wait_ms}")
        self.skipped = 0
        self.intake = FrameSetIntake(
            list(self.cameras), self._segment, slop_ns=int(self.config.slop_ms * 1e6), min_keys=1,
            max_wait_ns=int(self.config.max_wait_ms * 1e6), queue_size=max(10, self.config.queue_depth),
            latest_only=self.config.latest_only, on_start_over=self._start_over, on_error=self._work_failed,
            name=NODE_NAME)
        for name in self.cameras:
            create_image_subscription(self, f"{name}/image_raw", self.config.image_transport, self._callback(name),
                                      images_qos)
        self.create_service(Trigger, "~/relearn", self._relearn)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", RESULT_QOS)
        if self.config.diagnostics_period > 0:
            self.create_timer(self.config.diagnostics_period, self._publish_diagnostics)
        self.get_logger().info(
            f"segmenting {len(self.cameras)} cameras ({', '.join(self.cameras)}); background learnt "
            f"from {self.params.learn_from.replace('_', ' ')} (learn_frames {self.params.learn_frames})")

    def _callback(self, name: str):
        state = self.cameras[name]
        log = self.get_logger()

        def on_image(msg) -> None:
            try:
                rgb = decoded_rgb(msg)
                encoding = image_encoding(msg)
                is_colour(encoding)
            except ConversionError as err:
                log.error(f"{name}/image_raw: {err}", throttle_duration_sec=5.0)
                return
            if state.encoding is not None and is_colour(encoding) != is_colour(state.encoding):
                log.error(f"{name}/image_raw is {encoding}, the background was learnt from {state.encoding} "
                          f"frames: frame refused (~/relearn learns it anew)", throttle_duration_sec=5.0)
                return
            if state.model.shape is not None and rgb.shape[:2] != tuple(state.model.shape):
                state.size_errors += 1
                limit = self.config.relearn_after_size_errors
                if limit and state.size_errors >= limit:
                    log.warning(f"{name}: image size changed to {rgb.shape[1]}x{rgb.shape[0]}; relearning")
                    state.relearn_requested = True  # in the worker, before this frame
                else:
                    log.error(f"{name}/image_raw is {rgb.shape[1]}x{rgb.shape[0]}, the background was learnt at "
                              f"{state.model.shape[1]}x{state.model.shape[0]}: frame refused",
                              throttle_duration_sec=5.0)
                    return
            state.size_errors = 0
            self.intake.add(name, stamp_to_ns(msg.header.stamp), (rgb, encoding, msg.header.frame_id))

        return on_image

    def _segment(self, picked: PickedSet) -> None:
        """Segment one frame set's cameras and publish their masks (the intake's worker)."""
        self.skipped += picked.skipped
        for name, (rgb, encoding, frame_id) in picked.items.items():
            state = self.cameras[name]
            if state.relearn_requested:
                state.relearn()
            t0 = time.perf_counter()
            try:
                mask = state.model.apply(rgb, picked.stamp_ns)
            except ValueError as err:  # e.g. a size other than the one learnt
                self.get_logger().error(f"{name}: {err}; relearning", throttle_duration_sec=5.0)
                state.relearn()
                continue
            if state.encoding is None:
                state.encoding = encoding
            state.seconds += time.perf_counter() - t0
            state.frames += 1
            self.mask_pubs[name].publish(numpy_to_image(mask, "mono8", picked.stamp_ns, frame_id, self.factory))

    def _start_over(self, jump_ns: int) -> None:
        """The stamps went back (a bag replayed again): each camera's model forgets its last stamp."""
        self.get_logger().warning(f"the stamps went back by {jump_ns / 1e9:.2f} s: relearning the background")
        for state in self.cameras.values():
            state.relearn()

    def _work_failed(self, err: Exception) -> None:
        self.get_logger().error(f"frame set not segmented: {err!r}", throttle_duration_sec=5.0)

    def destroy_node(self) -> None:
        self.intake.close()
        super().destroy_node()

    def _relearn(self, _request, response):
        for state in self.cameras.values():
            state.relearn_requested = True  # in the worker, before its next frame
        response.success = True
        response.message = f"relearning the background of {len(self.cameras)} cameras"
        self.get_logger().info(response.message)
        return response

    def log_totals(self) -> None:
        """Frames segmented per camera (printed at shutdown, to compare with what was sent)."""
        self.get_logger().info("frames segmented: " + ", ".join(
            f"{name} {state.frames}" for name, state in self.cameras.items()))

    def _publish_diagnostics(self) -> None:
        out = DiagnosticArray()
        out.header.stamp = self.get_clock().now().to_msg()
        for name, state in self.cameras.items():
            ms = 1e3 * state.seconds / state.frames if state.frames else 0.0
            learning = state.model.is_learning
            out.status.append(DiagnosticStatus(
                level=DiagnosticStatus.OK, name=f"{NODE_NAME}: {name}", hardware_id=name,
                message="learning background" if learning else "segmenting",
                values=[KeyValue(key="frames", value=str(state.frames)),
                        KeyValue(key="ms_per_frame", value=f"{ms:.2f}")]))
        self.diag_pub.publish(out)


def main(args=None) -> int:
    return run_node(ForegroundSegmentation, NODE_NAME, __doc__, (ForegroundNodeConfig, ForegroundParams), args,
                    on_shutdown=lambda node: node.log_totals())


if __name__ == "__main__":
    raise SystemExit(main())
