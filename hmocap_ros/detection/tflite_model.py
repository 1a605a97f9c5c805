"""A TFLite model file run by LiteRT (``ai-edge-litert``, the TFLite runtime with XNNPACK), checked
when it is loaded (no rclpy).

The keypoint networks (:mod:`.keypoint_network`, :mod:`.pose_detector`) are TFLite files from
MediaPipe's wheel, shipped under ``hmocap_ros/data/models/`` (``SOURCES.md`` there). LiteRT runs
them with the XNNPACK delegate and does not depend on OpenCV's version (the apt OpenCV of ROS
Jazzy, 4.6, has no TFLite reader). :func:`load_model` turns every way a file can be wrong
(missing, a folder, not a TFLite flatbuffer, truncated, another model) into one
:class:`ModelFileError` whose message names the file and where to get it.

A :class:`TFLiteModel` is not thread-safe: give each thread its own. LiteRT releases the GIL
while it runs a model, so models in several threads run on several cores.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["MODEL_DIR", "ModelFileError", "TFLiteModel", "load_model"]

#: Where the shipped models lie.
MODEL_DIR = Path(__file__).resolve().parents[1] / "data" / "models"


class ModelFileError(RuntimeError):
    """A model file is missing, unreadable or not the expected model; the message names the
    file and where to get it."""


class TFLiteModel:
    """One LiteRT interpreter of a model with a single float32 input, its outputs by name.

    ``run(x)`` returns the named outputs (copies) in the order of ``outputs``.
    """

    def __init__(self, interpreter, outputs: tuple[str, ...]):
        self._interpreter = interpreter
        detail = interpreter.get_input_details()[0]
        self.input_shape = tuple(int(n) for n in detail["shape"])
        self._input = detail["index"]
        by_name = {d["name"]: d["index"] for d in interpreter.get_output_details()}
        self._outputs = [by_name[name] for name in outputs]

    def run(self, x: np.ndarray) -> list[np.ndarray]:
        self._interpreter.set_tensor(self._input, np.ascontiguousarray(x, dtype=np.float32))
        self._interpreter.invoke()
        return [self._interpreter.get_tensor(i).copy() for i in self._outputs]


def load_model(path: str | Path, what: str, outputs: dict[str, tuple[int, ...]],
               input_shape: tuple[int, ...], where: str, threads: int = 1) -> TFLiteModel:
    """The model at ``path`` on ``threads`` LiteRT threads, after checking that its input has
    ``input_shape`` and that it has each output of ``outputs`` (name -> shape), and that it
    runs once on zeros. ``what`` names the model and ``where`` says where to get it, in the
    :class:`ModelFileError` raised for a missing, corrupt or wrong file."""
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{what} {path} not found: {where}")
    try:
        from ai_edge_litert.interpreter import Interpreter
    except ImportError:
        raise ModelFileError(f"{what} {path} cannot be run: the LiteRT runtime is not installed "
                             f"(pip install ai-edge-litert)") from None
    try:
        interpreter = Interpreter(model_path=str(path), num_threads=max(1, int(threads)))
        interpreter.allocate_tensors()
    except (ValueError, RuntimeError) as error:
        reason = str(error).strip().splitlines()[0][:160] if str(error).strip() else "unreadable"
        raise ModelFileError(f"{what} {path} is corrupt or not a TFLite model ({reason}): "
                             f"{where}") from None
    inputs = interpreter.get_input_details()
    found = {d["name"]: tuple(int(n) for n in d["shape"]) for d in interpreter.get_output_details()}
    wrong = [f"{name} {shape}" for name, shape in outputs.items() if found.get(name) != shape]
    if len(inputs) != 1 or tuple(int(n) for n in inputs[0]["shape"]) != input_shape or wrong:
        raise ModelFileError(
            f"{what} {path} is another model (input "
            f"{[tuple(int(n) for n in d['shape']) for d in inputs]}, outputs {found}; expected "
            f"input {input_shape} and outputs {dict(outputs)}): {where}")
    model = TFLiteModel(interpreter, tuple(outputs))
    try:
        model.run(np.zeros(input_shape, np.float32))
    except (ValueError, RuntimeError) as error:
        raise ModelFileError(f"{what} {path} does not run ({str(error)[:160]}): {where}") from None
    return model
