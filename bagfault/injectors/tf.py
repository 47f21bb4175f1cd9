"""TF injector (`tf`, tf2_msgs/msg/TFMessage), anchor keys and meaning.

Every fault names the transform it targets with parent_frame and
child_frame. Drop and bias apply to matching transforms only; the delay
applies to the whole message.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, ClassVar

from bagfault.faults.combine import add
from bagfault.faults.rotation import add_rpy
from bagfault.injectors.base import Injector
from bagfault.schema import DELAY_MS, Key, double

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.faults.active import ActiveFault
    from bagfault.injectors.base import RawMessage


class TfInjector(Injector):
    """Translation and rotation bias and drop of one transform."""

    type_name = 'tf'
    description = 'tf2_msgs/msg/TFMessage: bias or drop of the parent_frame -> child_frame transform.'
    message_types = ('tf2_msgs/msg/TFMessage',)
    fields: ClassVar[tuple[Key, ...]] = (
        Key('parent_frame', 'non_empty_string', 'Parent frame id of the transform to affect.', required=True),
        Key('child_frame', 'non_empty_string', 'Child frame id of the transform to affect.', required=True),
        Key(
            'drop_probability', 'number', 'Probability that a matching transform is removed (0..1).', default=0.0,
            minimum=0.0, maximum=1.0
        ),
        DELAY_MS,
        double('x_bias', 'Added to transform.translation.x, in metres.', finite=False),
        double('y_bias', 'Added to transform.translation.y, in metres.', finite=False),
        double('z_bias', 'Added to transform.translation.z, in metres.', finite=False),
        double('roll_bias_deg', 'Added to the roll of transform.rotation, in degrees.', finite=False),
        double('pitch_bias_deg', 'Added to the pitch of transform.rotation, in degrees.', finite=False),
        double('yaw_bias_deg', 'Added to the yaw of transform.rotation, in degrees.', finite=False),
    )
    stream_keys = frozenset({'delay_ms', 'parent_frame', 'child_frame'})

    def process(self, message: RawMessage, active: Sequence[ActiveFault]) -> list[RawMessage]:
        """Drop is per transform here, so it happens inside `mutate`."""
        return self._process(message, active)

    def process_batch(self, messages: list[RawMessage], active: Sequence[ActiveFault]) -> list[RawMessage]:
        """Same as per message: TF streams are light."""
        return [out for message in messages for out in self._process(message, active)]

    def _process(self, message: RawMessage, active: Sequence[ActiveFault]) -> list[RawMessage]:
        if active and self.needs_decoding(active):
            message = self.mutate_batch([message], active)[0]
        return self.retime([message], active)

    def mutate(self, message: Any, time: int, active: Sequence[ActiveFault]) -> None:
        """Per transform: drop, then translation bias, then rotation bias, fault by fault."""
        kept = []
        for transform in message.transforms:
            matching = [f for f in active if _matches(f, transform)]
            if any(_drop(f) for f in matching):
                continue
            translation = transform.transform.translation
            for fault in matching:
                for axis in ('x', 'y', 'z'):
                    add(translation, axis, fault.config.get(f'{axis}_bias', 0.0))
            for fault in matching:
                roll, pitch, yaw = (fault.config.get(f'{k}_bias_deg', 0.0) for k in ('roll', 'pitch', 'yaw'))
                if roll or pitch or yaw:
                    add_rpy(transform.transform.rotation, math.radians(roll), math.radians(pitch), math.radians(yaw))
            kept.append(transform)
        message.transforms = kept


def _matches(fault: ActiveFault, transform: Any) -> bool:
    config = fault.config
    return bool(
        config.get('parent_frame') == transform.header.frame_id
        and config.get('child_frame') == transform.child_frame_id
    )


def _drop(fault: ActiveFault) -> bool:
    probability = fault.config.get('drop_probability', 0.0)
    if probability <= 0.0:
        return False
    if probability >= 1.0:
        return True
    return bool(fault.random.stream('drop_probability').random() < probability)
