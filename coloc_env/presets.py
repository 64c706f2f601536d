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

How exactly the parts reproduce each preset (tests/coloc_env):

* relay_ukf, gps_denied_nbp, lossy_fusion, bandwidth_fusion, mrclam_relay: bindings on the core
  (:mod:`coloc_env.scenarios.binding`): the scenario *is* the composition of its parts with the
  paper's action codec, observation, reward and info; ``PRESETS[name]`` is
  :meth:`~coloc_env.scenarios.binding.PresetScenario.compose` of the default config. relay_ukf:
  circles (no anchors) / relay (one next hop per holder) / ukf_dcl, team reward. gps_denied_nbp:
  gps_denied / broadcast (the ranging radius, no loss) / dnbp. lossy_fusion: target_cv /
  bernoulli_delay / prediction_compensation; its link outcomes are the network's draws
  (``LossyFusionScenario.link_outcomes``). bandwidth_fusion: drift / bandwidth (the preset's scored
  selection) / bandwidth_fusion, reporting xhat(k+1) after step k (the plain composition scores the
  one-step prediction xhat(k) against x(k), eq. 12's pairing). mrclam_relay: mrclam / relay
  (``routing="per_source"``: one next hop per measuring robot) / ukf_se2, the action vector passed
  verbatim, the team's mean error after the time update minus the team's hop cost. Each binding's test
  shows that the plain composition, handed the same world draws and network key, gives the preset's
  estimates (test_target_compositions, test_mrclam_preset_parts, test_relay_ukf_env,
  test_gps_denied_composition).
* nlos_horizon: nlos_orbit / random_delay / afge is equal to 1e-9 under AHG when the scenario is
  handed the delays the network drew (test_nlos_composition). It is not a binding yet: the scenario
  lets the agent see the packets that arrived at k before it picks the horizon for k, while the core
  decides before the readings of k (a composed afge agent sees step k - 1's packets and costs; AHG
  itself runs inside the backend on k's, so the paper policy is the same).
"""

from __future__ import annotations

from coloc_env.backends.nlos import Afge
from coloc_env.composition import Composition
from coloc_env.networks.random_delay import RandomDelay
from coloc_env.scenarios import REGISTRY
from coloc_env.scenarios.binding import PresetScenario
from coloc_env.worlds.nlos_orbit import NlosOrbit

_PARTS = {
    "nlos_horizon": (NlosOrbit(), RandomDelay(), Afge()),
}


def _preset(name: str) -> Composition:
    cls = REGISTRY[name]
    if issubclass(cls, PresetScenario):  # a binding on the core: its parts come from its config
        return cls.compose(cls.Config())
    return Composition(*_PARTS.get(name, (None, None, None)), preset=name)


PRESETS: dict[str, Composition] = {name: _preset(name) for name in REGISTRY}
