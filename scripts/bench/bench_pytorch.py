#!/usr/bin/env python3
"""PyTorch reference timings for `stagerl bench update` (issue 10): the same SAC, TD3 and DDPG
updates, written as CleanRL writes them, on the same shapes (obs 16, act 6, batch 256, hidden
h x h), one thread, median milliseconds per update.

Not part of the tests (torch is heavy). Run it in a venv with torch installed, in the same
session as the Rust figures:

    python scripts/bench/bench_pytorch.py --hidden 64 256 --updates 300
    target/release/stagerl bench update --algo sac --hidden 64

Prints one JSON line per (algo, hidden): {"algo", "hidden", "ms_per_update", "torch"}.
"""

import argparse
import json
import time

import torch
import torch.nn as nn
import torch.nn.functional as F

OBS, ACT, BATCH = 16, 6, 256
GAMMA, TAU = 0.95, 0.005


def mlp(sizes, out_act=None):
    layers = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(nn.ReLU())
    if out_act is not None:
        layers.append(out_act)
    return nn.Sequential(*layers)


def polyak(target, source):
    with torch.no_grad():
        for t, s in zip(target.parameters(), source.parameters()):
            t.mul_(1 - TAU).add_(s, alpha=TAU)


class Sac:
    """CleanRL's sac_continuous_action update (log-std tanh-bounded to [-5, 2], auto alpha)."""

    def __init__(self, h):
        self.actor = mlp([OBS, h, h, 2 * ACT])
        self.q = [mlp([OBS + ACT, h, h, 1]) for _ in range(2)]
        self.qt = [mlp([OBS + ACT, h, h, 1]) for _ in range(2)]
        for t, q in zip(self.qt, self.q):
            t.load_state_dict(q.state_dict())
        self.q_opt = torch.optim.Adam(list(self.q[0].parameters()) + list(self.q[1].parameters()), lr=1e-3)
        self.a_opt = torch.optim.Adam(self.actor.parameters(), lr=1e-3)
        self.log_alpha = torch.zeros(1, requires_grad=True)
        self.alpha_opt = torch.optim.Adam([self.log_alpha], lr=1e-3)

    def sample(self, obs):
        mean, s = self.actor(obs).chunk(2, dim=-1)
        log_std = -5 + 3.5 * (torch.tanh(s) + 1)
        std = log_std.exp()
        u = mean + std * torch.randn_like(mean)
        a = torch.tanh(u)
        logp = (-0.5 * ((u - mean) / std) ** 2 - log_std - 0.9189385332046727).sum(-1)
        logp = logp - torch.log(1 - a.pow(2) + 1e-6).sum(-1)
        return a, logp

    def update(self, o, a, r, o2, d):
        alpha = self.log_alpha.exp().detach()
        with torch.no_grad():
            a2, logp2 = self.sample(o2)
            x2 = torch.cat([o2, a2], 1)
            q_next = torch.min(self.qt[0](x2), self.qt[1](x2)).squeeze(-1) - alpha * logp2
            y = r + GAMMA * (1 - d) * q_next
        x = torch.cat([o, a], 1)
        q_loss = F.mse_loss(self.q[0](x).squeeze(-1), y) + F.mse_loss(self.q[1](x).squeeze(-1), y)
        self.q_opt.zero_grad()
        q_loss.backward()
        self.q_opt.step()
        pi, logp = self.sample(o)
        xp = torch.cat([o, pi], 1)
        a_loss = (alpha * logp - torch.min(self.q[0](xp), self.q[1](xp)).squeeze(-1)).mean()
        self.a_opt.zero_grad()
        a_loss.backward()
        self.a_opt.step()
        alpha_loss = (-self.log_alpha.exp() * (logp.detach() - ACT)).mean()
        self.alpha_opt.zero_grad()
        alpha_loss.backward()
        self.alpha_opt.step()
        for t, q in zip(self.qt, self.q):
            polyak(t, q)


class Td3:
    """CleanRL's td3_continuous_action update; one critic and delay 1 make it DDPG."""

    def __init__(self, h, critics=2, delay=2, smoothing=True):
        self.actor = mlp([OBS, h, h, ACT], nn.Tanh())
        self.actor_t = mlp([OBS, h, h, ACT], nn.Tanh())
        self.actor_t.load_state_dict(self.actor.state_dict())
        self.q = [mlp([OBS + ACT, h, h, 1]) for _ in range(critics)]
        self.qt = [mlp([OBS + ACT, h, h, 1]) for _ in range(critics)]
        for t, q in zip(self.qt, self.q):
            t.load_state_dict(q.state_dict())
        params = [p for q in self.q for p in q.parameters()]
        self.q_opt = torch.optim.Adam(params, lr=3e-4)
        self.a_opt = torch.optim.Adam(self.actor.parameters(), lr=3e-4)
        self.delay, self.smoothing, self.n = delay, smoothing, 0

    def update(self, o, a, r, o2, d):
        self.n += 1
        with torch.no_grad():
            a2 = self.actor_t(o2)
            if self.smoothing:
                a2 = (a2 + (torch.randn_like(a2) * 0.2).clamp(-0.5, 0.5)).clamp(-1, 1)
            x2 = torch.cat([o2, a2], 1)
            q_next = torch.stack([t(x2) for t in self.qt]).min(0).values.squeeze(-1)
            y = r + GAMMA * (1 - d) * q_next
        x = torch.cat([o, a], 1)
        q_loss = sum(F.mse_loss(q(x).squeeze(-1), y) for q in self.q)
        self.q_opt.zero_grad()
        q_loss.backward()
        self.q_opt.step()
        if self.n % self.delay == 0:
            a_loss = -self.q[0](torch.cat([o, self.actor(o)], 1)).mean()
            self.a_opt.zero_grad()
            a_loss.backward()
            self.a_opt.step()
            polyak(self.actor_t, self.actor)
            for t, q in zip(self.qt, self.q):
                polyak(t, q)


def bench(agent, updates):
    g = torch.Generator().manual_seed(0)
    o = torch.randn(BATCH, OBS, generator=g)
    a = torch.rand(BATCH, ACT, generator=g) * 2 - 1
    r = torch.randn(BATCH, generator=g)
    o2 = torch.randn(BATCH, OBS, generator=g)
    d = (torch.rand(BATCH, generator=g) < 0.1).float()
    for _ in range(20):
        agent.update(o, a, r, o2, d)
    times = []
    for _ in range(updates):
        t0 = time.perf_counter()
        agent.update(o, a, r, o2, d)
        times.append(time.perf_counter() - t0)
    times.sort()
    return 1e3 * times[len(times) // 2]


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--hidden", type=int, nargs="+", default=[64, 256])
    p.add_argument("--algo", nargs="+", default=["sac", "td3", "ddpg"])
    p.add_argument("--updates", type=int, default=300)
    args = p.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    make = {
        "sac": Sac,
        "td3": Td3,
        "ddpg": lambda h: Td3(h, critics=1, delay=1, smoothing=False),
    }
    for algo in args.algo:
        for h in args.hidden:
            ms = bench(make[algo](h), args.updates)
            print(json.dumps({"algo": algo, "hidden": h, "ms_per_update": round(ms, 3), "torch": torch.__version__}))


if __name__ == "__main__":
    main()
