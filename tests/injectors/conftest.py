"""Helpers to run one injector on hand-made messages."""

from __future__ import annotations

import pytest

from bagfault.demo import synthetic
from bagfault.faults.rng import FaultRandom
from bagfault.injectors.base import ActiveFault, RawMessage
from bagfault.io.types import Codec
from bagfault.spec.model import FaultSpec, InjectorSpec


class Harness:
    """Builds active faults and runs an injector type on messages."""

    def __init__(self) -> None:
        self.ts = synthetic.store()

    def faults(self, *configs: dict, seed: int = 0) -> list[ActiveFault]:
        out = []
        for number, config in enumerate(configs):
            spec = FaultSpec(id=f'f{number}', injector_id='inj', config=dict(config))
            out.append(ActiveFault(spec, 0, FaultRandom(seed, spec.id)))
        return out

    def injector(self, cls, msgtype: str):
        spec = InjectorSpec(id='inj', type=cls.type_name, input_topic='/in', output_topic='/out')
        return cls(spec, Codec(msgtype, self.ts))

    def run(self, cls, msgtype: str, messages: list, active: list[ActiveFault], *, batch: bool = False):
        injector = self.injector(cls, msgtype)
        raws = [RawMessage(i * 10, i * 10, bytes(self.ts.serialize_cdr(m, msgtype)), i) for i, m in enumerate(messages)]
        if batch:
            outs = injector.process_batch(raws, active)
        else:
            outs = [o for r in raws for o in injector.process(r, active)]
        return [(o.log_time, self.ts.deserialize_cdr(o.data, msgtype)) for o in outs], outs


@pytest.fixture
def harness() -> Harness:
    return Harness()
