"""The ``contention_localization`` benchmark table of docs/contention.md: every baseline on paired seeded episodes.

    python -m train.contention --episodes 32 --bound-episodes 8

Episode e is ``env.reset(seed=e)`` for every policy (paired: the same truth, readings and GPS faults), each
stochastic policy restarted with ``start_episode(e)``. Per policy: the episode's position error averaged over
its steps and UAVs (m), the frames sent and the link deliveries (the network's ``link_deliveries``: frames that
reached the centre) per episode, each with a 95 % interval (mean +- 1.96 s.e. over the episodes), and the paired
difference of each policy's error to ``always``'s. Bounds: ``coloc_env.pcrb`` under ``always`` and
``round_robin`` (centralized, local and delivered, as the root of the mean over steps and UAVs of tr, m).
"""

from __future__ import annotations

import argparse

import numpy as np

POLICIES = ("always", "round_robin", "aloha", "silent")


def play(name: str, episodes: int, preset: str = "contention_localization") -> dict[str, np.ndarray]:
    """Per episode: ``error`` (m), ``sent`` (frames), ``delivered`` (link deliveries) under policy ``name``."""
    import agents
    import coloc_env

    env = coloc_env.parallel_env(preset)
    policy = agents.make_policy(name, env, seed=0)
    out = {key: np.zeros(episodes) for key in ("error", "sent", "delivered")}
    for e in range(episodes):
        policy.start_episode(e)
        observations, _ = env.reset(seed=e)
        errors = []
        while env.agents:
            observations, _, _, _, infos = env.step(policy.act(observations))
            errors.append(np.mean([infos[a]["position_error"] for a in env.possible_agents]))
            out["sent"][e] += sum(infos[a]["messages_sent"] for a in env.possible_agents)
            out["delivered"][e] += sum(infos[a]["link_deliveries"] for a in env.possible_agents)
        out["error"][e] = np.mean(errors)
    return out


def interval(x: np.ndarray) -> str:
    half = 1.96 * np.std(x, ddof=1) / np.sqrt(len(x)) if len(x) > 1 else float("nan")
    return f"{np.mean(x):.2f} ± {half:.2f}"


def bounds(policy_name: str, episodes: int, preset: str = "contention_localization") -> dict[str, float]:
    import agents
    import coloc_env

    policy = policy_name
    if policy_name == "round_robin":
        policy = agents.make_policy("round_robin", coloc_env.parallel_env(preset)).act
    b = coloc_env.pcrb(preset, episodes=episodes, seed=0, policy=policy)
    return {key: float(np.sqrt(np.mean(b[key]))) for key in ("centralized", "local", "delivered")}


def table(episodes: int, bound_episodes: int) -> str:
    runs = {name: play(name, episodes) for name in POLICIES}
    lines = ["| policy | error (m) | paired error - always's (m) | frames sent | frames delivered |",
             "|---|---|---|---|---|"]
    for name, run in runs.items():
        lines.append(f"| `{name}` | {interval(run['error'])} | {interval(run['error'] - runs['always']['error'])} | "
                     f"{interval(run['sent'])} | {interval(run['delivered'])} |")
    best = min((n for n in POLICIES if n != "always"), key=lambda n: runs[n]["error"].mean())
    ratio = runs["always"]["error"].mean() / runs[best]["error"].mean()
    lines += ["", f"`always` loses to the best baseline, `{best}`: {ratio:.2f}x its mean error "
              f"(paired difference {interval(runs['always']['error'] - runs[best]['error'])} m).", "",
              "| bound (root of the mean tr over steps and UAVs, m) | centralized | local | delivered |",
              "|---|---|---|---|"]
    for name in ("always", "round_robin"):
        b = bounds(name, bound_episodes)
        lines.append(f"| `{name}` | {b['centralized']:.2f} | {b['local']:.2f} | {b['delivered']:.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--bound-episodes", type=int, default=8)
    args = parser.parse_args(argv)
    if not 2 <= args.episodes <= 100_000 or not 1 <= args.bound_episodes <= 100_000:
        parser.error("--episodes must be in 2..100000 and --bound-episodes in 1..100000")
    print(table(args.episodes, args.bound_episodes))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
