"""The paper scenarios as named Compositions: ``PRESETS[name]``.

A preset Composition names the parts it is made of and carries its binding:
the scenario class registered under the same name (its flat config, action
codec and observation). ``parallel_env(name)`` and ``parallel_env(PRESETS[name])``
build the same scenario, so they are bit-identical for the same seed and
actions.

| preset             | paper     | world        | network          | backend                   |
|--------------------|-----------|--------------|------------------|---------------------------|
| bandwidth_fusion   | zhao2020  | (drift)      | (bandwidth)      | (bandwidth_fusion)        |
| lossy_fusion       | fu2017    | (target_cv)  | (bernoulli_delay)| (prediction_compensation) |
| relay_ukf          | wang2019  | circles      | relay            | ukf_dcl                   |
| gps_denied_nbp     | wan2014   | gps_denied   | broadcast        | dnbp                      |
| nlos_horizon       | gao2016   | (nlos_orbit) | (random_delay)   | (afge)                    |
| mrclam_relay       | MRCLAM    | (mrclam)     | (relay)          | (ukf_se2)                 |

Parts in parentheses are not in the registries yet (issue 14 moves one paper
at a time onto the core); until then that preset's ``world`` / ``network`` /
``backend`` fields are None and its binding alone defines it.
"""

from __future__ import annotations

from coloc_env.backends.particles import Dnbp
from coloc_env.backends.ukf import UkfDcl
from coloc_env.composition import Composition
from coloc_env.networks import Broadcast, Relay
from coloc_env.scenarios import REGISTRY
from coloc_env.worlds import Circles
from coloc_env.worlds.gps_denied import GpsDenied

_PARTS = {
    "relay_ukf": (Circles(num_agents=4, num_anchors=0), Relay(loss_at_zero=0.0), UkfDcl()),
    # dnbp over this broadcast network gives the scenario's estimates exactly (test_gps_denied_composition)
    "gps_denied_nbp": (GpsDenied(), Broadcast(comm_range=300.0), Dnbp()),
}

PRESETS: dict[str, Composition] = {
    name: Composition(*_PARTS.get(name, (None, None, None)), preset=name) for name in REGISTRY
}
