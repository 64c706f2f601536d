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
| contention_localization | -    | gps_denied   | contention       | ukf_ccl                   |

How exactly the parts reproduce each preset (tests/coloc_env):

* Every preset is a binding on the core (``coloc_env.scenarios.binding``): the scenario *is* the
  composition of its parts with the paper's action codec, observation, reward and info;
  ``PRESETS[name]`` is ``coloc_env.scenarios.binding.PresetScenario.compose`` of the default
  config. relay_ukf: circles (no anchors) / relay (one next hop per holder) / ukf_dcl, team reward.
  gps_denied_nbp: gps_denied / broadcast (the ranging radius, no loss) / dnbp. lossy_fusion: target_cv /
  bernoulli_delay / prediction_compensation; its link outcomes are the network's draws
  (``LossyFusionScenario.link_outcomes``). bandwidth_fusion: drift / bandwidth (the preset's scored
  selection) / bandwidth_fusion, reporting xhat(k+1) after step k (the plain composition scores the
  one-step prediction xhat(k) against x(k), eq. 12's pairing). nlos_horizon: nlos_orbit / random_delay /
  afge, receiving before deciding (the agent sees stamp k's packets and the windows' costs before it
  picks the window of k); its packet delays are the network's draws (``coloc_env.backends.nlos.episode_delays``).
  mrclam_relay: mrclam / relay (``routing="per_source"``: one next hop per measuring robot) / ukf_se2, the
  action vector passed verbatim, the team's mean error after the time update minus the team's hop cost.
  Each binding's test shows that the plain composition, handed the same world draws and network key,
  gives the preset's estimates (test_target_compositions, test_mrclam_preset_parts, test_relay_ukf_env,
  test_gps_denied_composition, test_nlos_composition).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping

from coloc_env.composition import Composition
from coloc_env.scenarios import REGISTRY
from coloc_env.scenarios.binding import PresetScenario


def _preset(cls: type) -> Composition:
    if not issubclass(cls, PresetScenario):
        raise TypeError(f"scenario {cls.name!r} is not a binding on the composable core")
    return cls.compose(cls.Config())


class Presets(Mapping):
    """Name -> the preset's Composition, for every preset registered (``coloc_env.scenarios.REGISTRY``); each
    Composition is built once per registered class, when first asked for."""

    def __init__(self):
        self._built: dict[type, Composition] = {}

    def __getitem__(self, name: str) -> Composition:
        cls = REGISTRY[name]
        if cls not in self._built:
            self._built[cls] = _preset(cls)
        return self._built[cls]

    def __iter__(self) -> Iterator[str]:
        return iter(list(REGISTRY))

    def __len__(self) -> int:
        return len(REGISTRY)

    def __repr__(self) -> str:
        return f"Presets({list(self)})"


PRESETS = Presets()
for _name in REGISTRY:  # the presets' compositions are built (and validated) on import, as a check of their defaults
    PRESETS[_name]
