"""What a discrete MR.Q run's representation, value and policy say.

Loads each run's last checkpoint and its replay. On ``--batch`` transitions drawn from the replay
as the agent draws them (by priority, under their hindsight goals), it reads:

- the *spread* of the state embedding ``zs`` and of the state-action embedding ``zsa``: each
  unit's standard deviation over the batch, averaged over the units, beside a freshly initialised
  encoder's (an embedding whose spread falls far below the fresh one's has collapsed towards one
  point, which its model's next-embedding loss rewards);
- on the presses that ended their episode, right ones (reward 1 under the batch goal) and wrong
  ones apart: the reward the encoder's own model predicts, the value's target and the value (the
  twins' mean), all in the value's reward-scaled units but the model's reward.

And on ``--starts`` fresh start observations, with the agent's own networks:

- the value of each action (the clipped double Q, in the value's reward-scaled units) under every
  goal of the task, the observation otherwise unchanged: *goal spread* is how far apart the goals
  put an action's value, the most over the actions (0: the value does not read the goal);
- the policy's greedy action (its largest pre-activation) beside the value's best action.

    python studies/mrq_values.py runs/DA_mrqd_b64_100 [--starts 20] [--batch 4096]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from tactile_braille.agents.mrq import MRQAgent
from tactile_braille.agents.networks import observation_tensors
from tactile_braille.agents.report import load_run
from tactile_braille.agents.run import read_config
from tactile_braille.agents.training import make_replay


def load_agent(run: Path):
    """The run's environment and its agent at the last checkpoint (a discrete MR.Q run only)."""
    config, env, agent = load_run(run)
    if config.algo != "mrq" or not agent.discrete:
        raise ValueError(f"{run}: not a discrete MR.Q run; this reads a discrete MR.Q's value and policy")
    return env, agent


def load_replay(run: Path, env):
    """The run's replay as its last checkpoint left it."""
    files = sorted(run.glob("replay.*.npz"), key=lambda path: int(path.name.split(".")[1]))
    if not files:
        raise FileNotFoundError(f"{run}: no replay file (replay.EPOCH.npz)")
    buffer = make_replay(read_config(run), env)
    buffer.load(files[-1])
    return buffer


@torch.no_grad()
def replay_measures(env, agent, buffer, batch_size: int, seed: int) -> dict:
    """The embeddings' spread (the agent's and a fresh encoder's), and on the presses that ended their
    episode (PRESS is the last action), right and wrong apart: how many, the encoder's model's reward,
    the value's target, the value."""
    batch = agent.tensors(agent._draw(buffer, batch_size, np.random.default_rng(seed)))
    actions = agent._actions(batch["actions"])
    spread = {}
    for name, encoder in (("trained", agent.encoder), ("fresh", _fresh_encoder(env, agent))):
        zs = encoder.zs(batch["images"], batch["goals"], batch["previous_actions"]).float()
        zsa = encoder.zsa(zs, actions).float()
        spread[name] = (float(zs.std(0).mean()), float(zsa.std(0).mean()))
    zs = agent.encoder.zs(batch["images"], batch["goals"], batch["previous_actions"])
    _, _, logits = agent.encoder.predict(zs, actions)
    model_reward = (logits.float().softmax(-1) * agent.two_hot.values).sum(-1)
    target = agent._targets(batch)
    value = agent.value(agent.encoder.zsa(zs, actions), batch["goals"]).float().mean(-1)
    ended = (batch["actions"].long() == agent.action_size - 1) & (batch["horizon_dones"][:, 0] > 0)
    right = batch["horizon_rewards"][:, 0] > 0
    presses = {}
    for name, where in (("right", ended & right), ("wrong", ended & ~right)):
        presses[name] = {
            "count": int(where.sum()), "model_reward": float(model_reward[where].mean()),
            "target": float(target[where].mean()), "value": float(value[where].mean()),
        }  # fmt: skip
    return {"spread": spread, "presses": presses}


def _fresh_encoder(env, agent):
    torch.manual_seed(0)
    return MRQAgent(env.observation_space, env.action_space, agent.config, str(agent.device)).encoder


@torch.no_grad()
def start_measures(env, agent, starts: int, seed: int) -> list[dict]:
    """Per start observation: ``values`` (goals x actions), the policy's greedy action and the value's
    best action under the asked goal."""
    actions = torch.eye(agent.action_size)
    rows = []
    for start in range(starts):
        observation, _ = env.reset(seed=seed + start)
        goals = np.eye(len(observation["desired_goal"]), dtype=np.float32)
        values = []
        for goal in goals:
            images, goal, previous = observation_tensors({**observation, "desired_goal": goal}, agent.device)
            zs = agent.encoder.zs(images, goal, previous).float().expand(agent.action_size, -1)
            goal = goal.expand(agent.action_size, -1)
            values.append(agent.value(agent.encoder.zsa(zs, actions), goal).float().min(-1).values.numpy())
        values = np.asarray(values)
        asked = int(observation["desired_goal"].argmax())
        images, goal, previous = observation_tensors(observation, agent.device)
        zs = agent.encoder.zs(images, goal, previous).float()
        greedy = int(agent.policy(zs, goal).argmax())
        rows.append({"values": values, "goal": asked, "greedy": greedy, "best": int(values[asked].argmax())})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--starts", type=int, default=20, help="start observations read (default 20)")
    parser.add_argument("--seed", type=int, default=1000, help="the first start's seed (default 1000)")
    parser.add_argument("--batch", type=int, default=4096, help="replay transitions read (default 4096)")
    args = parser.parse_args()
    for run in args.runs:
        env, agent = load_agent(run)
        replay = replay_measures(env, agent, load_replay(run, env), args.batch, args.seed)
        (zs, zsa), (fresh_zs, fresh_zsa) = replay["spread"]["trained"], replay["spread"]["fresh"]
        print(f"{run}: {args.batch} replay transitions")
        print(f"  spread of zs {zs:.3f} (fresh encoder {fresh_zs:.3f}), of zsa {zsa:.3f} ({fresh_zsa:.3f})")
        for name, press in replay["presses"].items():
            print(
                f"  {name} presses ({press['count']}): model's reward {press['model_reward']:.3f}, value "
                f"{press['value']:.2f} against target {press['target']:.2f}"
            )
        rows = start_measures(env, agent, args.starts, args.seed)
        spread = [float(np.ptp(row["values"], axis=0).max()) for row in rows]
        print(f"  {len(rows)} starts")
        print(f"  goal spread of the values: median {np.median(spread):.3f}, largest {max(spread):.3f}")
        agree = sum(r["greedy"] == r["best"] for r in rows)
        print(f"  the policy's greedy action is the value's best: {agree}")
        for row in rows:
            print(
                f"  goal {row['goal']}: values {np.round(row['values'][row['goal']], 2)}, policy "
                f"{row['greedy']}, value's best {row['best']}"
            )


if __name__ == "__main__":
    main()
