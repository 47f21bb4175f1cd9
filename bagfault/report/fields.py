"""Before/after values of mutated fields, read back from the input and the output after a run.

Fields are shown as they are: a scalar field as its value per message (the
report adds after - before); an orientation as the angle a fault changes
(`pose.pose.orientation:yaw`, degrees, from the quaternion as tf2's getRPY
takes it, so q and -q are the same angle); an array field (LaserScan ranges, joint
velocities) as an element x time image, each time column the minimum of its
messages with any `inf` / `nan` kept in masks of their own, so a blind sector
shows as what it is. Faulted PointCloud2 topics get their point counts and a
bird's-eye view at the fault start, Image topics a thumbnail before and after
the fault start. Scalars keep every message (the page decimates them to
min/max envelopes); images have at most COLUMNS x ROWS cells.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from bagfault.errors import FieldPathError
from bagfault.faults.fieldpath import FieldPath
from bagfault.injectors.base import Injector
from bagfault.injectors.registry import get_injector_type
from bagfault.io.sources import InputSet
from bagfault.io.types import TypeCatalog
from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

    from bagfault.engine.result import RunResult
    from bagfault.spec.model import FaultSpec, InjectorSpec

COLUMNS, ROWS = 300, 360
CLOUD_POINTS, THUMB_WIDTH = 4000, 160
CLOUD, IMAGE = 'sensor_msgs/msg/PointCloud2', 'sensor_msgs/msg/Image'
ANGLES = ('roll', 'pitch', 'yaw')


def angle_of(field: str) -> tuple[str, str] | None:
    """(quaternion path, angle) of a plotted angle such as `pose.pose.orientation:yaw`; None for a field."""
    path, _, angle = field.rpartition(':')
    return (path, angle) if path and angle in ANGLES else None


def euler_deg(q: Any, angle: str) -> float:
    """Roll, pitch or yaw in degrees of a geometry_msgs Quaternion (fixed axes x, y, z: tf2's getRPY)."""
    x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    if angle == 'roll':
        value = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    elif angle == 'pitch':
        value = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    else:
        value = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return float(np.degrees(value))


@dataclass
class ArrayImage:
    """An array field over time: per time column (s) and element bin the minimum finite value, and where any
    message in the cell held inf or nan."""

    times: np.ndarray
    elements: np.ndarray
    values: np.ndarray   # (ROWS, COLUMNS), nan where no finite value
    inf: np.ndarray      # bool, same shape
    nan: np.ndarray      # bool, same shape
    span: float = 0.0    # seconds per column (the time columns are where messages fell, on this grid)


@dataclass
class FieldPlot:
    """One field of one injector: values before (input topic) and after (output topic)."""

    injector_id: str
    input_topic: str
    output_topic: str
    field: str
    before: tuple[list[float], list[float]] = dataclasses.field(default_factory=lambda: ([], []))
    after: tuple[list[float], list[float]] = dataclasses.field(default_factory=lambda: ([], []))
    faults: list[str] = dataclasses.field(default_factory=list)
    before_image: ArrayImage | None = None
    after_image: ArrayImage | None = None
    element_axis: str = 'element'


@dataclass
class MediaPlot:
    """A faulted PointCloud2 or Image topic: point counts, and what it looked like at the fault start."""

    injector_id: str
    msgtype: str
    input_topic: str
    output_topic: str
    faults: list[str]
    start_s: float
    counts_before: tuple[list[float], list[float]] = dataclasses.field(default_factory=lambda: ([], []))
    counts_after: tuple[list[float], list[float]] = dataclasses.field(default_factory=lambda: ([], []))
    snapshot_before: Any = None   # cloud: (x, y) arrays; image: (H, W, 3) uint8
    snapshot_after: Any = None


def plan(result: RunResult) -> tuple[list[FieldPlot], list[MediaPlot]]:
    """Fields touched by faults that were active during the run, and faulted cloud/image topics."""
    activated = _first_activations(result)
    plots, media = [], []
    for spec in result.scenario.injectors:
        found = _message_injector(spec)
        if found is None:
            continue
        cls, input_topic, output_topic = found
        active = [f for f in result.scenario.faults_of(spec.id) if f.id in activated]
        plots += [FieldPlot(spec.id, input_topic, output_topic, path, faults=sorted(set(faults)))
                  for path, faults in _plotted_fields(cls, active).items()]
        media += _media_plots(spec.id, cls, (input_topic, output_topic), active,
                              [activated[f.id] - (result.stats.origin or 0) for f in active])
    return plots, media


def _media_plots(injector_id: str, cls: type[Injector], topics: tuple[str, str], active: list[FaultSpec],
                 starts: list[int]) -> list[MediaPlot]:
    """The plot of a cloud or image injector whose faults were active (from the first, `starts` in ns from time
    zero); none for other types."""
    kinds = set(cls.message_types) & {CLOUD, IMAGE}
    if not active or len(kinds) != 1:
        return []
    return [MediaPlot(injector_id, kinds.pop(), *topics, sorted(f.id for f in active), min(starts) / NS)]


def _first_activations(result: RunResult) -> dict[str, int]:
    """Fault id -> when it first became active."""
    activated: dict[str, int] = {}
    for event in result.stats.events:
        if event.state == 'active':
            activated.setdefault(event.fault_id, event.time)
    return activated


def _message_injector(spec: InjectorSpec) -> tuple[type[Injector], str, str] | None:
    """The injector type and topics of a spec that changes messages from one topic to another (None for others)."""
    cls = get_injector_type(spec.type)
    if cls is None or not issubclass(cls, Injector) or not spec.input_topic or not spec.output_topic:
        return None
    return cls, spec.input_topic, spec.output_topic


def _plotted_fields(cls: type[Injector], active: list[FaultSpec]) -> dict[str, list[str]]:
    """Field path -> the active faults whose config keys change it (as the injector type says)."""
    fields: dict[str, list[str]] = {}
    for fault in active:
        for key in fault.config:
            for path in cls.plot_fields(key, fault.config):
                fields.setdefault(path, []).append(fault.id)
    return fields


class _ImageBuilder:
    """Accumulates an array field into a COLUMNS x ROWS image of minima and inf/nan masks."""

    def __init__(self, duration: float) -> None:
        self.duration = max(duration, 1e-9)
        self.values = np.full((ROWS, COLUMNS), np.inf)
        self.inf = np.zeros((ROWS, COLUMNS), dtype=bool)
        self.nan = np.zeros((ROWS, COLUMNS), dtype=bool)
        self.seen = np.zeros(COLUMNS, dtype=bool)
        self.size = 0

    def add(self, seconds: float, values: np.ndarray) -> None:
        values = np.asarray(values, dtype=float).ravel()
        if values.size == 0:
            return
        self.size = max(self.size, values.size)
        column = min(COLUMNS - 1, max(0, int(seconds / self.duration * COLUMNS)))
        index = np.arange(values.size)
        rows = index if values.size <= ROWS else (index * ROWS) // values.size  # longer arrays: ROWS bins
        finite = np.isfinite(values)
        np.minimum.at(self.values[:, column], rows[finite], values[finite])
        self.inf[rows[np.isinf(values)], column] = True
        self.nan[rows[np.isnan(values)], column] = True
        self.seen[column] = True

    def image(self, first: float, step: float) -> ArrayImage:
        used = min(ROWS, self.size) if self.size else 0
        values = np.where(np.isinf(self.values), np.nan, self.values)[:used]
        columns = np.flatnonzero(self.seen)
        times = (columns + 0.5) * self.duration / COLUMNS
        elements = first + np.arange(used) * step * max(self.size, 1) / max(used, 1)
        return ArrayImage(times, elements, values[:, columns], self.inf[:used, columns],
                          self.nan[:used, columns], self.duration / COLUMNS)


def _read(paths: list[Path], topic: str, fields: list[str], origin: int, duration: float,
          ) -> dict[str, tuple[list[float], list[float]] | _ImageBuilder]:
    """Scalar series or array images of `fields` on one topic."""
    out: dict[str, tuple[list[float], list[float]] | _ImageBuilder] = {}
    with InputSet(paths) as inputs:
        catalog = TypeCatalog(inputs.channels, inputs.ros_distro)
        channels = {i: c for i, c in enumerate(inputs.channels) if c.topic == topic}
        if not channels:
            return out
        msgtype = next(iter(channels.values())).msgtype
        codec = catalog.codec(msgtype)
        if codec is None:
            return out
        resolved, angles = _resolved(fields, msgtype, codec.store)
        for text in angles:
            out[text] = ([], [])
        for text in resolved:
            out[text] = _ImageBuilder(duration) if '[*]' in text else ([], [])
        for channel, time, _, data in inputs.messages():
            if channel in channels:
                _sample(out, codec.decode(data), (time - origin) / NS, resolved, angles)
    return out


def _resolved(fields: list[str], msgtype: str, store: Any) -> tuple[dict[str, FieldPath], dict[str, tuple[str, str]]]:
    """The fields as paths of the type, and the Euler angles of quaternions (roll/pitch/yaw of a path);
    a field the type does not have is left out."""
    resolved, angles = {}, {}
    for text in fields:
        found = angle_of(text)
        if found is not None:
            angles[text] = found
            continue
        try:
            resolved[text] = FieldPath.parse(text).resolve(msgtype, store)
        except FieldPathError:
            continue
    return resolved, angles


def _sample(out: dict[str, tuple[list[float], list[float]] | _ImageBuilder], message: Any, seconds: float,
            resolved: dict[str, FieldPath], angles: dict[str, tuple[str, str]]) -> None:
    """One message's value of every field: an angle in degrees, a scalar (an array's mean), or an image column."""
    for text, (path_text, angle) in angles.items():
        quaternion = _attribute_path(message, path_text)
        series = out[text]
        assert not isinstance(series, _ImageBuilder)
        series[0].append(seconds)
        series[1].append(float('nan') if quaternion is None else euler_deg(quaternion, angle))
    for text, path in resolved.items():
        target = out[text]
        if isinstance(target, _ImageBuilder):
            target.add(seconds, path.read(message))
        else:
            values = np.asarray(path.read(message), dtype=float)
            target[0].append(seconds)   # the value itself; nan and inf stay what they are
            target[1].append(float(values.mean()) if values.size else float('nan'))


def _attribute_path(message: Any, path: str) -> Any:
    """The sub-message at a dotted path of plain fields (None where the type has no such field)."""
    for name in path.split('.'):
        message = getattr(message, name, None)
        if message is None:
            return None
    return message


def _scan_axis(paths: list[Path], topic: str) -> tuple[float, float] | None:
    """(angle_min, angle_increment) in degrees of the first LaserScan on a topic, or None."""
    with InputSet(paths) as inputs:
        catalog = TypeCatalog(inputs.channels, inputs.ros_distro)
        channels = {i: c for i, c in enumerate(inputs.channels)
                    if c.topic == topic and c.msgtype == 'sensor_msgs/msg/LaserScan'}
        if not channels:
            return None
        codec = catalog.codec('sensor_msgs/msg/LaserScan')
        for channel, _, _, data in inputs.messages():
            if channel in channels and codec is not None:
                scan = codec.decode(data)
                return float(np.degrees(scan.angle_min)), float(np.degrees(scan.angle_increment))
    return None


def cloud_xy(message: Any) -> tuple[np.ndarray, np.ndarray]:
    """x and y of up to CLOUD_POINTS points of a PointCloud2 with FLOAT32 x and y."""
    offsets = {f.name: f.offset for f in message.fields if f.datatype == 7}
    if 'x' not in offsets or 'y' not in offsets or not message.point_step:
        return np.zeros(0), np.zeros(0)
    raw = np.asarray(message.data, dtype=np.uint8)
    count = raw.size // message.point_step
    points = raw[: count * message.point_step].reshape(count, message.point_step)
    points = points[:: max(1, count // CLOUD_POINTS)]
    order = '>f4' if message.is_bigendian else '<f4'
    x = np.ascontiguousarray(points[:, offsets['x']:offsets['x'] + 4]).view(order).ravel()
    y = np.ascontiguousarray(points[:, offsets['y']:offsets['y'] + 4]).view(order).ravel()
    keep = np.isfinite(x) & np.isfinite(y)
    return x[keep].astype(float), y[keep].astype(float)


def thumbnail(message: Any) -> np.ndarray | None:
    """An Image as an RGB uint8 array at most THUMB_WIDTH wide, or None for an encoding not shown."""
    encoding = str(message.encoding).lower()
    channels = {'rgb8': 3, 'bgr8': 3, 'rgba8': 4, 'bgra8': 4, 'mono8': 1, '8uc1': 1, 'mono16': 1, '16uc1': 1,
                '32fc1': 1}.get(encoding)
    if channels is None or not message.width or not message.height:
        return None
    dtype = {'mono16': 'u2', '16uc1': 'u2', '32fc1': 'f4'}.get(encoding, 'u1')
    dtype = ('>' if message.is_bigendian else '<') + dtype
    item = np.dtype(dtype).itemsize
    raw = np.asarray(message.data, dtype=np.uint8)
    rows = raw[: message.height * message.step].reshape(message.height, message.step)
    pixels = np.ascontiguousarray(rows[:, : message.width * channels * item]).view(dtype)
    pixels = pixels.reshape(message.height, message.width, channels)
    step = max(1, -(-message.width // THUMB_WIDTH))
    pixels = pixels[::step, ::step].astype(float)
    if item > 1:
        finite = pixels[np.isfinite(pixels)]
        high = float(finite.max()) if finite.size else 1.0
        pixels = np.nan_to_num(pixels / (high or 1.0) * 255.0)
    if encoding.startswith('bgr'):
        pixels = pixels[:, :, [2, 1, 0]]
    rgb = np.repeat(pixels, 3, axis=2) if channels == 1 else pixels[:, :, :3]
    return np.asarray(np.clip(rgb, 0, 255), dtype=np.uint8)


def _media(plot: MediaPlot, paths: list[Path], topic: str, origin: int,
           ) -> tuple[tuple[list[float], list[float]], Any]:
    """Point counts over time and the first message at or after the fault start, as a snapshot."""
    with InputSet(paths) as inputs:
        catalog = TypeCatalog(inputs.channels, inputs.ros_distro)
        channels = {i for i, c in enumerate(inputs.channels) if c.topic == topic and c.msgtype == plot.msgtype}
        codec = catalog.codec(plot.msgtype)
        if not channels or codec is None:
            return ([], []), None
        timed = (((time - origin) / NS, data) for channel, time, _, data in inputs.messages() if channel in channels)
        if plot.msgtype == CLOUD:
            return _cloud_counts(timed, codec, plot.start_s)
        return ([], []), _first_image(timed, codec, plot.start_s)


def _first_image(timed: Iterator[tuple[float, Any]], codec: Any, start_s: float) -> Any:
    """A thumbnail of the first image at or after `start_s` (None if there is none)."""
    for seconds, data in timed:
        if seconds >= start_s:
            return thumbnail(codec.decode(data))
    return None


def _cloud_counts(timed: Iterator[tuple[float, Any]], codec: Any, start_s: float,
                  ) -> tuple[tuple[list[float], list[float]], Any]:
    """A cloud topic's point count over time, and the x and y of its first cloud at or after `start_s`."""
    counts: tuple[list[float], list[float]] = ([], [])
    snapshot: Any = None
    for seconds, data in timed:
        message = codec.decode(data)
        counts[0].append(seconds)
        counts[1].append(float(message.width * message.height))
        if snapshot is None and seconds >= start_s:
            snapshot = cloud_xy(message)
    return counts, snapshot


def _fill(plot: FieldPlot, before: tuple[list[float], list[float]] | _ImageBuilder | None,
          after: tuple[list[float], list[float]] | _ImageBuilder | None, axis: tuple[float, float] | None) -> None:
    """A plot's series or images before and after; a scan's ranges along its angles."""
    scan = axis is not None and plot.field == 'ranges[*]'
    for side, data in (('before', before), ('after', after)):
        if isinstance(data, _ImageBuilder):
            first, step = axis if axis is not None and scan else (0.0, 1.0)
            setattr(plot, f'{side}_image', data.image(first, step))
        elif data is not None:
            setattr(plot, side, data)
    if scan:
        plot.element_axis = 'angle (deg)'


def collect(result: RunResult) -> tuple[list[FieldPlot], list[MediaPlot]]:
    """Fill before/after series and images of every planned plot."""
    plots, media = plan(result)
    if (not plots and not media) or result.output is None or result.stats.origin is None:
        return plots, media
    origin = result.stats.origin
    duration = ((result.stats.last_time or origin) - origin) / NS
    by_topic: dict[tuple[str, str], list[FieldPlot]] = {}
    for plot in plots:
        by_topic.setdefault((plot.input_topic, plot.output_topic), []).append(plot)
    _fill_series(result, by_topic, origin, duration)
    for item in media:
        item.counts_before, item.snapshot_before = _media(item, list(result.inputs), item.input_topic, origin)
        item.counts_after, item.snapshot_after = _media(item, [result.output], item.output_topic, origin)
    return plots, media


def _fill_series(result: RunResult, by_topic: dict[tuple[str, str], list[FieldPlot]], origin: int,
                 duration: float) -> None:
    """Each topic pair's plots, read once from the inputs and once from the output."""
    assert result.output is not None
    for (input_topic, output_topic), group in by_topic.items():
        fields = [p.field for p in group]
        before = _read(list(result.inputs), input_topic, fields, origin, duration)
        after = _read([result.output], output_topic, fields, origin, duration)
        axis = _scan_axis(list(result.inputs), input_topic)
        for plot in group:
            _fill(plot, before.get(plot.field), after.get(plot.field), axis)
