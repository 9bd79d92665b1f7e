"""The networks (agents/networks.py): the squashed Gaussian policy's log-probabilities, critics with poses,
the released code's dueling split, plain Q heads and initial weights."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn
from torch.distributions import Normal, TanhTransform, TransformedDistribution

from feature_agents import ACTIONS, FEATURES, GOALS, PREVIOUS
from tactile_braille.agents.common import POSE_SIZE
from tactile_braille.agents.networks import (
    LOG_STD_MAX,
    LOG_STD_MIN,
    RELEASED_LOG_STD_MIN,
    TRUNCATED_NORMAL_STD,
    ContinuousQNetwork,
    DeterministicPolicy,
    DuelingQNetwork,
    GaussianPolicy,
    PolicyNetwork,
)

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_gaussian_policy_log_prob_matches_torch_distributions():
    torch.manual_seed(0)
    policy = GaussianPolicy(3, 4, 3, hidden=(32,))
    with torch.no_grad():  # spread the heads so the tanh correction and the std both matter
        nn.init.normal_(policy.mean.weight, std=0.5)
        nn.init.normal_(policy.log_std.weight, std=0.3)
        policy.log_std.bias.fill_(-0.5)
    size = 64
    generator = torch.Generator().manual_seed(1)
    images = ((torch.rand(size, 1, 100, 100, generator=generator) < 0.3) * 255).to(torch.uint8)
    goals = torch.eye(4)[torch.randint(4, (size,), generator=generator)]
    previous = torch.rand(size, 3, generator=generator) * 2 - 1

    torch.manual_seed(123)
    action, log_prob, deterministic = policy(images, goals, previous)
    with torch.no_grad():
        hidden = policy.trunk(images, goals, previous)
        mean = policy.mean(hidden).double()
        log_std = policy.log_std(hidden).double().clamp(LOG_STD_MIN, LOG_STD_MAX)
    torch.manual_seed(123)  # the forward pass draws its noise first thing from the global generator
    noise = torch.randn(mean.shape).double()
    raw = mean + log_std.exp() * noise
    distribution = TransformedDistribution(Normal(mean, log_std.exp()), TanhTransform(cache_size=1))
    squashed = distribution.transforms[0](raw)  # cached: log_prob inverts it exactly
    expected = distribution.log_prob(squashed).sum(-1)

    assert mean.abs().max() > 1.5  # samples reach the saturated part of tanh
    gaussian_only = Normal(mean, log_std.exp()).log_prob(raw).sum(-1)
    assert (expected - gaussian_only).abs().max() > 1.0  # the Jacobian term is not negligible here
    assert log_prob.shape == (size,)
    np.testing.assert_allclose(log_prob.detach().double(), expected, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(action.detach().double(), squashed, atol=1e-6)
    np.testing.assert_allclose(deterministic.detach().double(), torch.tanh(mean), atol=1e-6)
    assert action.abs().max() <= 1.0 and deterministic.abs().max() <= 1.0
    assert not torch.allclose(action, deterministic)  # the sample explores
    # The sample is reparameterised: its log-probability carries gradients to the heads.
    log_prob.sum().backward()
    assert policy.log_std.weight.grad is not None and policy.log_std.weight.grad.abs().sum() > 0


def test_an_asymmetric_critic_takes_poses_and_a_plain_one_refuses_them():
    torch.manual_seed(0)
    sizes = (ACTIONS, GOALS, PREVIOUS, (16,))
    asymmetric = ContinuousQNetwork(*sizes, pose_size=POSE_SIZE, features=FEATURES)
    plain = ContinuousQNetwork(*sizes, features=FEATURES)
    inputs = (torch.randn(5, FEATURES), torch.eye(GOALS)[:1].repeat(5, 1), torch.zeros(5, PREVIOUS),
              torch.zeros(5, ACTIONS))  # fmt: skip
    poses = torch.randn(5, POSE_SIZE)
    assert asymmetric(*inputs, poses).shape == (5,) and plain(*inputs).shape == (5,)
    torch.nn.init.normal_(asymmetric.q.weight)  # away from the near-zero start, so the pose shows
    assert not torch.allclose(asymmetric(*inputs, poses), asymmetric(*inputs, poses + 1.0))
    with pytest.raises(ValueError, match="needs poses of size 3, got none"):
        asymmetric(*inputs)
    with pytest.raises(ValueError, match="takes no poses"):
        plain(*inputs, poses)
    with pytest.raises(ValueError, match="pose_size must be at least 0"):
        ContinuousQNetwork(*sizes, pose_size=-1, features=FEATURES)


@pytest.mark.parametrize("goal_heads", [False, True])
def test_a_split_dueling_head_reads_half_the_units_each(goal_heads):
    """The released code's dueling network: the value head on the first half of the last dense
    layer's units, the advantage head on the second half."""
    torch.manual_seed(0)
    net = DuelingQNetwork(ACTIONS, GOALS, PREVIOUS, hidden=(64,), features=FEATURES, goal_heads=goal_heads,
                          dueling_split=True)  # fmt: skip
    assert (net.value.in_features, net.advantage.in_features) == (32, 32)
    features, previous = torch.randn(5, FEATURES), torch.randn(5, PREVIOUS)
    goals = torch.eye(GOALS)[torch.tensor([0, 1, 2, 3, 1])]
    with torch.no_grad():
        hidden = net.trunk(features, previous) if goal_heads else net.trunk(features, goals, previous)
        value, advantage = net.value(hidden[:, :32]), net.advantage(hidden[:, 32:])
        if goal_heads:  # the goal's own head
            rows = goals.argmax(-1)
            value = value[torch.arange(5), rows, None]
            advantage = advantage.unflatten(-1, (GOALS, ACTIONS))[torch.arange(5), rows]
        expected = value + advantage - advantage.mean(-1, keepdim=True)
        assert torch.allclose(net(features, goals, previous), expected, atol=1e-6)
        whole = DuelingQNetwork(ACTIONS, GOALS, PREVIOUS, hidden=(64,), features=FEATURES)
        assert (whole.value.in_features, whole.advantage.in_features) == (64, 64)


def released_layers(network: nn.Module) -> int:
    """Check that every convolution and dense layer of ``network`` has zero biases and weights within
    two LeCun deviations (the released code's truncated normals); returns how many there are."""
    layers = [m for m in network.modules() if isinstance(m, nn.Conv2d | nn.Linear)]
    for layer in layers:
        bound = 2 * (1.0 / layer.weight[0].numel()) ** 0.5 / TRUNCATED_NORMAL_STD
        assert torch.all(layer.bias == 0) and layer.weight.abs().max() <= bound
    return len(layers)


def test_released_weights_are_lecun_truncated_normals_in_every_layer_and_head():
    torch.manual_seed(0)
    net = DuelingQNetwork(ACTIONS, GOALS, PREVIOUS, weights_init="released")
    assert released_layers(net) == 3 + 1 + 2  # the paper's convolutions, its dense layer, the two heads
    dense = net.trunk.dense[0].weight  # 512 x 5,191 draws: their deviation is LeCun's
    assert dense.std().item() == pytest.approx((1.0 / dense.shape[1]) ** 0.5, rel=0.01)
    ours = DuelingQNetwork(ACTIONS, GOALS, PREVIOUS)
    assert ours.value.weight.std() < 0.02 < net.value.weight.std()  # ours start the heads near zero
    with pytest.raises(ValueError, match="weights_init must be 'he' or 'released', got 'glorot'"):
        DuelingQNetwork(ACTIONS, GOALS, PREVIOUS, weights_init="glorot")


@pytest.mark.parametrize("goal_heads", [False, True])
def test_plain_q_heads_give_the_head_s_outputs_as_q_values(goal_heads):
    """``dueling=False`` (the released discrete SAC's critics): no value head; the one head's outputs,
    the goal's row of them with goal heads, are the Q-values, under one goal and under every goal."""
    torch.manual_seed(0)
    net = DuelingQNetwork(ACTIONS, GOALS, PREVIOUS, hidden=(64,), features=FEATURES, goal_heads=goal_heads,
                          dueling=False)  # fmt: skip
    assert net.value is None and net.advantage.in_features == 64
    features, previous = torch.randn(5, FEATURES), torch.randn(5, PREVIOUS)
    goals = torch.eye(GOALS)[torch.tensor([0, 1, 2, 3, 1])]
    with torch.no_grad():
        hidden = net.trunk(features, previous) if goal_heads else net.trunk(features, goals, previous)
        expected = net.advantage(hidden)
        if goal_heads:
            expected = expected.unflatten(-1, (GOALS, ACTIONS))[torch.arange(5), goals.argmax(-1)]
        assert torch.allclose(net(features, goals, previous), expected, atol=1e-6)
        every = net.every_goal(features, previous)
        assert every.shape == (5, GOALS, ACTIONS)
        assert torch.allclose(every[torch.arange(5), goals.argmax(-1)], expected, atol=1e-6)
        assert not torch.allclose(expected - expected.mean(-1, keepdim=True), expected)  # not centred
    with pytest.raises(ValueError, match="dueling_split splits a dueling network's units"):
        DuelingQNetwork(ACTIONS, GOALS, PREVIOUS, features=FEATURES, dueling=False, dueling_split=True)


@pytest.mark.parametrize("weights_init", ["he", "released"])
def test_a_goal_difference_network_values_where_the_goal_lies_from_the_observation(weights_init):
    """``goal_difference``: the goal leaves the trunk; the values read the difference of the
    observation's learnt place and the goal's, so two goals at one place are valued alike and a
    shift of every place together changes nothing; every goal's values at once are each goal's own."""
    torch.manual_seed(0)
    net = DuelingQNetwork(ACTIONS, GOALS, PREVIOUS, hidden=(64,), features=FEATURES, goal_difference=3,
                          weights_init=weights_init)  # fmt: skip
    assert net.trunk.dense[0].in_features == FEATURES + PREVIOUS  # no goal in the trunk
    features, previous = torch.randn(5, FEATURES), torch.randn(5, PREVIOUS)
    goals = torch.eye(GOALS)[torch.tensor([0, 1, 2, 3, 1])]
    with torch.no_grad():
        values = net(features, goals, previous)
        assert not torch.allclose(values, net(features, torch.roll(goals, 1, dims=-1), previous))
        every = net.every_goal(features, previous)
        assert every.shape == (5, GOALS, ACTIONS)
        assert torch.allclose(every[torch.arange(5), goals.argmax(-1)], values, atol=1e-6)
        shift = torch.randn(3)
        net.difference.place.bias += shift  # every place moves by the same vector
        net.difference.goal_place.weight += shift[:, None]
        assert torch.allclose(net(features, goals, previous), values, atol=1e-5)
        places = net.difference.goal_place.weight
        places[:, 2] = places[:, 0]  # goal 2 at goal 0's place
        every = net.every_goal(features, previous)
        assert torch.allclose(every[:, 2], every[:, 0]) and not torch.allclose(every[:, 1], every[:, 0])
    with pytest.raises(ValueError, match="through goal_heads or goal_difference, not both"):
        DuelingQNetwork(ACTIONS, GOALS, PREVIOUS, features=FEATURES, goal_heads=True, goal_difference=3)


def test_the_policy_network_takes_the_released_initial_weights_where_asked():
    torch.manual_seed(0)
    policy = PolicyNetwork(ACTIONS, GOALS, PREVIOUS, weights_init="released")
    assert released_layers(policy) == 3 + 1 + 1  # the paper's convolutions, its dense layer, the logits head
    assert PolicyNetwork(ACTIONS, GOALS, PREVIOUS).logits.weight.std() < 0.02 < policy.logits.weight.std()
    with pytest.raises(ValueError, match="weights_init must be 'he' or 'released', got 'xavier'"):
        PolicyNetwork(ACTIONS, GOALS, PREVIOUS, weights_init="xavier")


@pytest.mark.parametrize("network", [ContinuousQNetwork, GaussianPolicy, DeterministicPolicy])
def test_released_continuous_networks_take_lecun_layers_and_glorot_heads(network):
    """The released SAC's and TD3's networks: TensorFlow's variance scaling for the convolutions and
    dense layers, its dense default (Glorot uniform, zero biases) for the output layers."""
    torch.manual_seed(0)
    net = network(ACTIONS, GOALS, PREVIOUS, hidden=(64,), weights_init="released")
    heads = [m for name, m in net.named_children() if isinstance(m, nn.Linear)]
    assert released_layers(net.trunk) == 3 + 1  # the paper's convolutions and the dense layer
    for head in heads:
        glorot = (6.0 / (head.in_features + head.out_features)) ** 0.5
        assert torch.all(head.bias == 0) and head.weight.abs().max() <= glorot
        assert head.weight.abs().max() > 0.8 * glorot  # uniform up to the bound, not near zero as ours
    ours = network(ACTIONS, GOALS, PREVIOUS, hidden=(64,))
    assert all(head.weight.std() < 0.02 for head in ours.children() if isinstance(head, nn.Linear))
    with pytest.raises(ValueError, match="weights_init must be 'he' or 'released', got 'glorot'"):
        network(ACTIONS, GOALS, PREVIOUS, weights_init="glorot")


def test_actions_join_the_networks_scaled_as_the_released_code_reads_them_in_mm():
    """``action_scale`` s: a network fed actions a behaves as the unscaled one fed s * a (same weights)."""
    torch.manual_seed(0)
    size, scale = 8, 10.0
    images = ((torch.rand(size, 1, 100, 100) < 0.3) * 255).to(torch.uint8)
    goals = torch.eye(GOALS)[torch.randint(GOALS, (size,))]
    previous, actions = torch.rand(size, ACTIONS) * 2 - 1, torch.rand(size, ACTIONS) * 2 - 1
    critic = ContinuousQNetwork(ACTIONS, GOALS, PREVIOUS, hidden=(32,), action_scale=scale)
    plain = ContinuousQNetwork(ACTIONS, GOALS, PREVIOUS, hidden=(32,))
    plain.load_state_dict(critic.state_dict())
    with torch.no_grad():
        scaled_q = critic(images, goals, previous, actions)
        torch.testing.assert_close(scaled_q, plain(images, goals, scale * previous, scale * actions))
        assert not torch.allclose(scaled_q, plain(images, goals, previous, actions))
        actor = DeterministicPolicy(ACTIONS, GOALS, PREVIOUS, hidden=(32,), action_scale=scale)
        plain_actor = DeterministicPolicy(ACTIONS, GOALS, PREVIOUS, hidden=(32,))
        plain_actor.load_state_dict(actor.state_dict())
        torch.testing.assert_close(
            actor(images, goals, previous), plain_actor(images, goals, scale * previous)
        )
    with pytest.raises(ValueError, match="action_scale must be positive, got 0"):
        GaussianPolicy(ACTIONS, GOALS, PREVIOUS, action_scale=0)


def test_the_released_log_deviation_runs_through_a_tanh_onto_its_bounds():
    hidden = torch.randn(16, 32)
    policy = GaussianPolicy(ACTIONS, GOALS, PREVIOUS, hidden=(32,), log_std="tanh", features=FEATURES)
    ours = GaussianPolicy(ACTIONS, GOALS, PREVIOUS, hidden=(32,), features=FEATURES)
    with torch.no_grad():
        for bias, released, clamped in ((0.0, -9.0, 0.0), (50.0, LOG_STD_MAX, LOG_STD_MAX),
                                        (-50.0, RELEASED_LOG_STD_MIN, LOG_STD_MIN)):  # fmt: skip
            for net in (policy, ours):
                net.log_std.weight.zero_()
                net.log_std.bias.fill_(bias)
            assert torch.all(policy.log_deviation(hidden) == released)
            assert torch.all(ours.log_deviation(hidden) == clamped)
        policy.log_std.bias.fill_(0.5)  # between the bounds: the tanh's curve, not a clamp
        expected = RELEASED_LOG_STD_MIN + 0.5 * (LOG_STD_MAX - RELEASED_LOG_STD_MIN) * (np.tanh(0.5) + 1)
        torch.testing.assert_close(policy.log_deviation(hidden), torch.full((16, ACTIONS), float(expected)))
    with pytest.raises(ValueError, match="log_std must be one of"):
        GaussianPolicy(ACTIONS, GOALS, PREVIOUS, log_std="softplus")
