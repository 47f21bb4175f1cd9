"""Raw image injector (`image`): noise, dead pixels, stuck frame, brightness, black frame.

Works on sensor_msgs/msg/Image with encodings rgb8, bgr8, mono8, mono16 and
32FC1, respecting row padding (`step`) and byte order; pixel values stay
in the encoding's range. Dead pixels are chosen once per fault activation,
like a real sensor's.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from bagfault.errors import InjectorError
from bagfault.faults.combine import strongest
from bagfault.injectors.base import Injector
from bagfault.schema import DELAY_MS, DROP_PROBABILITY, Key, boolean, probability

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.faults.active import ActiveFault

ENCODINGS = {'rgb8': ('u1', 3), 'bgr8': ('u1', 3), 'mono8': ('u1', 1), 'mono16': ('u2', 1), '32FC1': ('f4', 1)}


def pixels(message: Any) -> np.ndarray:
    """height x width x channels array (a copy) of the image data."""
    if message.encoding not in ENCODINGS:
        raise InjectorError(f'image encoding {message.encoding!r} is not supported '
                                  f'({", ".join(ENCODINGS)})')
    kind, channels = ENCODINGS[message.encoding]
    dtype = np.dtype(('>' if message.is_bigendian else '<') + kind)
    raw = np.asarray(message.data, dtype=np.uint8)[: message.height * message.step]
    rows = raw.reshape(message.height, message.step)[:, : message.width * channels * dtype.itemsize]
    return np.ascontiguousarray(rows).view(dtype).reshape(message.height, message.width, channels).copy()


def store_pixels(message: Any, image: np.ndarray) -> None:
    """Write pixels back (rows packed, step updated)."""
    kind, _ = ENCODINGS[message.encoding]
    dtype = np.dtype(('>' if message.is_bigendian else '<') + kind)
    data = image.astype(dtype, copy=False)
    message.step = data.shape[1] * data.shape[2] * dtype.itemsize
    message.data = np.frombuffer(data.tobytes(), dtype=np.uint8)


class ImageInjector(Injector):
    """Pixel faults on raw images."""

    type_name = 'image'
    description = 'sensor_msgs/msg/Image (rgb8, bgr8, mono8, mono16, 32FC1): noise, dead pixels, stuck/black frame.'
    message_types = ('sensor_msgs/msg/Image',)
    fields: ClassVar[tuple[Key, ...]] = (
        DROP_PROBABILITY,
        DELAY_MS,
        Key('noise_stddev', 'number', 'Gaussian noise per pixel value, stddev in pixel units of the encoding.',
                    default=0.0, minimum=0.0),
        probability('dead_pixel_fraction', 'Share of pixels that read 0, fixed for the fault (0..1).'),
        boolean('stuck_frame', 'Repeat the first frame seen while the fault is active.'),
        Key('brightness_scale', 'number', 'Multiplies every pixel value (factor), clipped to the range.',
                    default=1.0, minimum=0.0),
        boolean('black_frame', 'Every pixel reads 0.'),
    )

    def __init__(self, spec: Any, codec: Any = None, faults: Sequence[Any] = ()) -> None:
        super().__init__(spec, codec, faults)
        self._stuck: dict[tuple[str, int], tuple[Any, ...]] = {}
        self._dead: dict[tuple[str, int, tuple[int, ...]], np.ndarray] = {}

    def mutate(self, message: Any, time: int, active: Sequence[ActiveFault]) -> None:
        """Stuck frame, brightness, noise, dead pixels, black frame."""
        for fault in active:
            if fault.config.get('stuck_frame'):
                key = (fault.id, fault.since)
                if key not in self._stuck:
                    self._stuck[key] = (message.height, message.width, message.encoding, message.is_bigendian,
                                        message.step, np.array(message.data, copy=True))
                (message.height, message.width, message.encoding, message.is_bigendian, message.step,
                 data) = self._stuck[key]
                message.data = data.copy()
                break
        touched = {k for f in active for k in f.config} & {'noise_stddev', 'dead_pixel_fraction',
                                                            'brightness_scale', 'black_frame'}
        if not touched:
            return
        image = pixels(message)
        floating = image.dtype.kind == 'f'
        values = image.astype(np.float64)
        scale, owner = strongest(active, 'brightness_scale', 1.0)
        if owner is not None and scale != 1.0:
            values *= scale
        sigma, owner = strongest(active, 'noise_stddev')
        if owner is not None and sigma > 0:
            values += owner.random.stream('noise_stddev').standard_normal(values.shape) * sigma
        fraction, owner = strongest(active, 'dead_pixel_fraction')
        if owner is not None and fraction > 0:
            dead_key = (owner.id, owner.since, tuple(image.shape[:2]))
            if dead_key not in self._dead:
                self._dead[dead_key] = owner.random.stream('dead_pixel_fraction').random(image.shape[:2]) < fraction
            values[self._dead[dead_key]] = 0.0
        if any(f.config.get('black_frame') for f in active):
            values[:] = 0.0
        if not floating:
            info = np.iinfo(image.dtype)
            values = np.clip(np.rint(values), info.min, info.max)
        store_pixels(message, values.astype(image.dtype))
