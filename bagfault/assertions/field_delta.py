"""`field_delta`: output minus input of a field, message by message.

Pairs each output message with the input message it came from: by
header.stamp when the type has a header (delays and drops keep stamps),
otherwise by log time. The condition (`during`/`outside`) is taken at the
input message's time.
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from bagfault.assertions.base import AssertionType, window_problems
from bagfault.assertions.fields import resolve_on_topic
from bagfault.assertions.windows import DURING, OUTSIDE, describe, in_window
from bagfault.errors import AssertionSetupError
from bagfault.schema import Key
from bagfault.units import NS

if TYPE_CHECKING:
    from bagfault.assertions.runner import AssertionRunner
    from bagfault.spec.model import AssertionSpec, Scenario

HORIZON = 60 * NS  # unmatched inputs older than this are forgotten (dropped messages)


class FieldDeltaAssertion(AssertionType):
    """delta = output - input of `field` must equal `equals` +- tolerance where the window holds,
    and `otherwise` (if given) elsewhere."""

    type_name = 'field_delta'
    description = 'Output minus input of a field equals a value (bias really applied), during/outside a fault.'
    fields: ClassVar[tuple[Key, ...]] = (
        Key('topic', 'non_empty_string', 'Output topic.', required=True),
        Key('input_topic', 'non_empty_string', 'Input topic; default: input of the injector writing topic.'),
        Key('field', 'non_empty_string', 'Field path, e.g. pose.pose.position.x.', required=True),
        Key('equals', 'number', 'Expected output - input where the window holds (field unit).', required=True),
        Key('otherwise', 'number', 'Expected output - input elsewhere (field unit).'),
        Key('tolerance', 'number', 'Accepted absolute error (field unit).', default=1e-9, minimum=0.0),
        DURING,
        OUTSIDE,
    )
    takes_within = False

    @classmethod
    def check(cls, spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
        """Windows name faults; input topic known or derivable."""
        problems = window_problems(spec, scenario)
        if 'otherwise' in spec.params and not {'during', 'outside'} & set(spec.params):
            problems.append(('otherwise', "needs 'during' or 'outside'"))
        if 'input_topic' not in spec.params and 'topic' in spec.params:
            writer = next((i for i in scenario.injectors if i.output_topic == spec.params['topic']), None)
            if writer is None:
                problems.append(('', f"no injector writes {spec.params['topic']}: give 'input_topic'"))
            elif writer.input_topic == writer.output_topic:
                problems.append(('topic', f"{spec.params['topic']} is injected in place, so its input is not in the "
                                          'output; use an injector with a separate output_topic'))
        return problems

    def __init__(self, spec: AssertionSpec, runner: AssertionRunner) -> None:
        super().__init__(spec, runner)
        params = self.params
        self.input_topic: str = params.get('input_topic') or next(
            (i.input_topic for i in runner.scenario.injectors if i.output_topic == params['topic'] and i.input_topic),
            '')
        self.tolerance = params.get('tolerance', 1e-9)
        self.pending_inputs: dict[Any, deque[tuple[int, np.ndarray, bool]]] = {}
        self.order: deque[tuple[int, Any]] = deque()
        self.compared = 0
        self.worst = 0.0  # the largest |delta - expected| so far (tolerance - worst is the margin)
        self.path: Any = None

    def topics(self) -> set[str]:
        """Input and output topics."""
        return {self.params['topic'], self.input_topic}

    decoded_topics = topics

    def prepare(self) -> None:
        """Both topics must carry the same type with the field."""
        types = self.runner.topic_types
        out, inp = str(self.params['topic']), self.input_topic
        if out == inp:
            raise AssertionSetupError(f'topic and input_topic are both {out}')
        if out in types and inp in types and types[out] != types[inp]:
            raise AssertionSetupError(f'{out} carries {types[out]} but {inp} carries {types[inp]}')
        self.path = resolve_on_topic(self.runner, out, self.params['field'])
        resolve_on_topic(self.runner, inp, self.params['field'])

    @staticmethod
    def _key(message: Any, time: int) -> Any:
        header = getattr(message, 'header', None)
        if header is not None and hasattr(header, 'stamp'):
            return (header.stamp.sec, header.stamp.nanosec, getattr(header, 'frame_id', ''))
        return time

    def on_message(self, topic: str, time: int, message: Any) -> None:
        """Remember inputs; compare each output with its input."""
        key = self._key(message, time)
        if topic == self.input_topic:
            self.pending_inputs.setdefault(key, deque()).append((time, self.path.read(message), in_window(self)))
            self.order.append((time, key))
            while self.order and self.order[0][0] < time - HORIZON:
                _, old = self.order.popleft()
                queue = self.pending_inputs.get(old)
                if queue:
                    queue.popleft()
                    if not queue:
                        del self.pending_inputs[old]
            return
        queue = self.pending_inputs.get(key)
        if not queue:
            return
        in_time, before, condition = queue.popleft()
        if not queue:
            del self.pending_inputs[key]
        after = self.path.read(message)
        if after.shape != before.shape:
            self.fail(time, f"at {self.runner.t(time)} {self.params['field']} has {after.size} values on {topic} but "
                            f'{before.size} on {self.input_topic}')
            return
        expected = self.params['equals'] if condition else self.params.get('otherwise')
        if expected is None:
            return
        delta = after - before
        finite = np.isfinite(before) & np.isfinite(after)
        error = np.where(finite, np.abs(delta - expected), 0.0)
        bad = finite & (error > self.tolerance)
        self.compared += 1
        if bad.any():
            index = int(np.argmax(bad))
            where = f' (element {index})' if delta.size > 1 else ''
            window = describe(self) if condition else f' (not{describe(self)})'
            self.fail(time, f"at {self.runner.t(in_time)} {self.params['field']}{where} changed by {delta[index]:.9g}, "
                            f'expected {expected:g} +- {self.tolerance:g}{window}',
                      margin=self.tolerance - float(error[index]))
        elif error.size:
            self.worst = max(self.worst, float(error.max()))

    def finish(self, time: int) -> None:
        """Pass if pairs were compared."""
        if self.compared:
            self.passed(time, f"{self.compared} message pairs {self.input_topic} -> {self.params['topic']} had the "
                              f"expected change of {self.params['field']}", margin=self.tolerance - self.worst)
        else:
            self.fail(time, f"no message pair {self.input_topic} -> {self.params['topic']} compared: "
                            'not observed before the end of the bag')
