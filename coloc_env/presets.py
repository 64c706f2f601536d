"""The paper scenarios as named Compositions: ``PRESETS[name]``.

A preset Composition names the parts it is made of and carries its binding:
the scenario class registered under the same name (its flat config, action
codec and observation). ``parallel_env(name)`` and ``parallel_env(PRESETS[name])``
build the same scenario, so they are bit-identical for the same seed and
actions.

| preset             | paper     | world        | network          | backend                   |
|--------------------|-----------|--------------|------------------|---------------------------|
| bandwidth_fusion   | zhao2020  | drift        | bandwidth        | bandwidth_fusion          |
| lossy_fusion       | fu2017    | target_cv    | bernoulli_delay  | prediction_compensation   |
| relay_ukf          | wang2019  | circles      | relay            | ukf_dcl                   |
| gps_denied_nbp     | wan2014   | gps_denied   | broadcast        | dnbp                      |
| nlos_horizon       | gao2016   | nlos_orbit   | random_delay     | afge                      |
| mrclam_relay       | MRCLAM    | mrclam       | relay            | ukf_se2                   |

How exactly the parts reproduce each binding (tests/coloc_env):

* relay_ukf: a binding on the core (:mod:`coloc_env.scenarios.binding`): its scenario *is* the
  composition of circles (no anchors) / relay / ukf_dcl with the paper's action codec, observation and
  team reward; ``PRESETS["relay_ukf"]`` is :meth:`RelayUKFScenario.compose` of the default config;
* gps_denied_nbp: a binding too: gps_denied / broadcast (the ranging radius, no loss) / dnbp;
* bandwidth_fusion: drift / bandwidth / bandwidth_fusion with the paper's component tables gives
  the scenario's estimates to 1e-9, reported one step earlier (the composition scores the one-step
  prediction xhat(k) against x(k), eq. 12's pairing; test_target_compositions);
* lossy_fusion, nlos_horizon: equal to 1e-9 when the scenario is handed the link outcomes (delays,
  losses) the network drew; on its own seed the scenario draws them from its single episode
  generator, while a network draws from its own child generator, so that every backend sees the
  same world (test_target_compositions, test_nlos_composition).
* mrclam_relay: mrclam / relay (``routing="per_source"``: the scenario's routing table, one next hop per
  measuring robot) / ukf_se2, with the scenario's action vector passed verbatim, gives the scenario's
  estimates and covariance factors to 1e-9 when the scenario replays the window the world drew and gets
  the loss uniforms the network drew (the scenario draws the offset and the losses from its episode
  generator; the world and the network from their own children), and the same messages per holder and
  hop cost per step (test_mrclam_preset_parts). Its reward stays the binding's: the team's mean error
  after the time update minus the team's hop cost (a composition: each agent's own error after the
  measurement update, minus ``communication_cost`` per message; the relay network accounts the hop cost
  in ``cost_sent`` but the composed reward does not subtract it); so does its observation.
"""

from __future__ import annotations

from coloc_env.backends.fusion import BandwidthFusion, PredictionCompensation
from coloc_env.backends.nlos import Afge
from coloc_env.backends.ukf_se2 import UkfSe2
from coloc_env.composition import Composition
from coloc_env.networks import Relay
from coloc_env.networks.bandwidth import Bandwidth
from coloc_env.networks.bernoulli_delay import BernoulliDelay
from coloc_env.networks.random_delay import RandomDelay
from coloc_env.scenarios import REGISTRY
from coloc_env.scenarios.binding import PresetScenario
from coloc_env.worlds.drift import Drift
from coloc_env.worlds.mrclam import Mrclam
from coloc_env.worlds.nlos_orbit import NlosOrbit
from coloc_env.worlds.target_cv import TargetCv

_PARTS = {
    "bandwidth_fusion": (Drift(), Bandwidth(), BandwidthFusion()),
    "lossy_fusion": (TargetCv(), BernoulliDelay(), PredictionCompensation()),
    "nlos_horizon": (NlosOrbit(), RandomDelay(), Afge()),
    # data=None: $COLOC_MRCLAM_DATA is read only when an env is built; a loss-free relay with the scenario's
    # per-source routing table (test_mrclam_preset_parts)
    "mrclam_relay": (Mrclam(), Relay(loss_at_zero=0.0, routing="per_source"), UkfSe2()),
}



def _preset(name: str) -> Composition:
    cls = REGISTRY[name]
    if issubclass(cls, PresetScenario):  # a binding on the core: its parts come from its config
        return cls.compose(cls.Config())
    return Composition(*_PARTS.get(name, (None, None, None)), preset=name)


PRESETS: dict[str, Composition] = {name: _preset(name) for name in REGISTRY}
