"""Excitation generators: amplitude bound, determinism, streaming/replay, and each signal's own properties."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fcrlive.constants import PAPER_EXCITATION_STD_PU, TSO_PERIODS_S
from fcrlive.errors import ConfigError
from fcrlive.excitation import (
    GuardLimits,
    MultisineGenerator,
    PrbsGenerator,
    SafetyGuard,
    SineGenerator,
    WhiteNoiseGenerator,
    crest_factor,
    hz_to_pu,
    make_generator,
    pu_to_hz,
    replay,
)
from fcrlive.excitation.generators import PRBS_TAPS


def small_multisine(**kw):
    # 300 s record at 0.5 s: fast to build, still holds all ten TSO periods in distinct bins
    return MultisineGenerator(sample_time_s=0.5, record_samples=600, **kw)


FACTORIES = {
    "white": lambda a, s: WhiteNoiseGenerator(amplitude_hz=a, seed=s, sample_time_s=0.1),
    "white_held": lambda a, s: WhiteNoiseGenerator(amplitude_hz=a, seed=s, hold_samples=3, sigma_factor=2.0),
    "prbs": lambda a, s: PrbsGenerator(amplitude_hz=a, seed=s, order=7, clock_samples=3),
    "multisine": lambda a, s: small_multisine(amplitude_hz=a, seed=s),
    "multisine_random": lambda a, s: small_multisine(amplitude_hz=a, seed=s, phases="random"),
    "sine": lambda a, s: SineGenerator(amplitude_hz=a, seed=s, period_s=10.0, phase_rad=0.3),
}
kinds = st.sampled_from(sorted(FACTORIES))


# ---- common guarantees ------------------------------------------------------------------------------------

@settings(max_examples=60, deadline=None)
@given(kinds, st.floats(1e-4, 0.1), st.integers(0, 2**63 - 1), st.lists(st.integers(0, 700), max_size=5))
def test_amplitude_bound_and_block_split_invariance(kind, amp, seed, cuts):
    g = FACTORIES[kind](amp, seed)
    total = sum(cuts) + 50
    blocks = [g.next_block(n) for n in [*cuts, 50]]
    x = np.concatenate(blocks)
    assert x.shape == (total,) and np.all(np.isfinite(x))
    assert np.max(np.abs(x)) <= amp
    whole = FACTORIES[kind](amp, seed).next_block(total)
    np.testing.assert_array_equal(x, whole)  # independent of how the stream is cut


@settings(max_examples=30, deadline=None)
@given(kinds, st.integers(0, 10**9), st.integers(0, 2000), st.integers(1, 300))
def test_state_seek_and_description_replay(kind, seed, start, n):
    g = FACTORIES[kind](0.1, seed)
    g.next_block(start)
    state = json.loads(json.dumps(g.state))  # the state is JSON-able
    expected = g.next_block(n)
    g.next_block(17)
    g.restore(state)
    np.testing.assert_array_equal(g.next_block(n), expected)
    g.seek(start)
    np.testing.assert_array_equal(g.next_block(n), expected)
    desc = json.loads(json.dumps(g.description.to_dict()))  # stored with the samples
    np.testing.assert_array_equal(replay(desc, start, n), expected)
    assert make_generator(desc).description == g.description


@pytest.mark.parametrize("kind", ["white", "prbs", "multisine_random"])
def test_seed_matters(kind):
    a = FACTORIES[kind](0.1, 1).next_block(500)
    b = FACTORIES[kind](0.1, 2).next_block(500)
    assert not np.array_equal(a, b)


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"amplitude_hz": 0.2}, "amplitude_hz"), ({"amplitude_hz": 0.0}, "amplitude_hz"),
    ({"amplitude_hz": math.nan}, "amplitude_hz"), ({"sample_time_s": -0.1}, "sample_time_s"),
    ({"seed": -1}, "seed"), ({"seed": 1.5}, "seed"), ({"hold_samples": 0}, "hold_samples"),
])
def test_bad_generator_parameters_rejected(kwargs, name):
    with pytest.raises(ConfigError, match=name):
        WhiteNoiseGenerator(**kwargs)


def test_bad_kind_specific_parameters_rejected():
    with pytest.raises(ConfigError, match="order"):
        PrbsGenerator(order=40)
    with pytest.raises(ConfigError, match="record_samples"):  # 10 s record: 40/50/60 … s collide in bin 0
        MultisineGenerator(sample_time_s=0.1, record_samples=100)
    with pytest.raises(ConfigError, match="phases"):
        MultisineGenerator(phases="zero")
    with pytest.raises(ConfigError, match="kind"):
        make_generator({"kind": "chirp", "seed": 0, "amplitude_hz": 0.1, "sample_time_s": 0.1})
    with pytest.raises(ConfigError):
        make_generator({"kind": "white"})


def test_pu_conversion():
    g = WhiteNoiseGenerator(seed=4)
    x = g.next_block(10)
    g.seek(0)
    np.testing.assert_allclose(g.next_block_pu(10), x / 50.0)
    np.testing.assert_allclose(pu_to_hz(hz_to_pu(x)), x)


def test_generator_through_guard_stays_within_guard_limits():
    g = small_multisine(amplitude_hz=0.1)
    lim = GuardLimits(amplitude_hz=0.08, rate_limit_hz_per_s=0.05, holdoff_s=1.0, stale_after_s=1.0)
    guard = SafetyGuard(lim)
    r = g.next_block(600)
    out = np.array([guard.step(0.5 * k, float(v), 50.0, 0b11).value_hz for k, v in enumerate(r)])
    assert np.max(np.abs(out)) <= 0.08
    assert np.max(np.abs(np.diff(out))) <= 0.05 * 0.5 + 1e-15
    assert np.count_nonzero(out) > 500


# ---- white noise ------------------------------------------------------------------------------------------

def test_white_noise_is_the_papers():
    g = WhiteNoiseGenerator.paper(seed=0)
    assert g.sigma_hz == pytest.approx(PAPER_EXCITATION_STD_PU * 50.0)
    assert g.amplitude_hz == pytest.approx(0.1)
    assert g.std_hz / g.sigma_hz == pytest.approx(0.9866, abs=1e-4)  # truncation at 3σ


def test_white_noise_statistics():
    g = WhiteNoiseGenerator(amplitude_hz=0.1, seed=11)
    x = g.next_block(200_000)
    assert x.std() == pytest.approx(0.1 / 3, rel=0.02)  # "std ≈ amplitude/3"
    assert x.std() == pytest.approx(g.std_hz, rel=0.01)
    assert abs(x.mean()) < 4 * g.std_hz / math.sqrt(x.size)
    assert np.max(np.abs(x)) <= 0.1 and np.max(np.abs(x)) > 0.095  # truncated, not clipped to atoms
    assert np.count_nonzero(np.abs(x) == 0.1) <= 1
    xc = x - x.mean()
    for lag in (1, 2, 5):
        rho = np.dot(xc[:-lag], xc[lag:]) / np.dot(xc, xc)
        assert abs(rho) < 4 / math.sqrt(x.size)  # white


def test_white_noise_hold():
    x = WhiteNoiseGenerator(seed=2, hold_samples=4).next_block(40)
    assert np.all(x.reshape(10, 4) == x.reshape(10, 4)[:, :1])
    assert len(np.unique(x)) == 10


# ---- PRBS -------------------------------------------------------------------------------------------------

def _gf2_mulmod(a: int, b: int, mod: int, n: int) -> int:
    r = 0
    while b:
        if b & 1:
            r ^= a
        b >>= 1
        a <<= 1
        if a >> n & 1:
            a ^= mod
    return r


def _gf2_powmod_x(e: int, mod: int, n: int) -> int:
    result, base = 1, 0b10
    while e:
        if e & 1:
            result = _gf2_mulmod(result, base, mod, n)
        base = _gf2_mulmod(base, base, mod, n)
        e >>= 1
    return result


def _prime_factors(m: int) -> set[int]:
    out, p = set(), 2
    while p * p <= m:
        while m % p == 0:
            out.add(p)
            m //= p
        p += 1
    if m > 1:
        out.add(m)
    return out


@pytest.mark.parametrize("order", sorted(PRBS_TAPS))
def test_prbs_taps_are_primitive(order):
    poly = 1
    for t in PRBS_TAPS[order]:
        poly |= 1 << t
    assert PRBS_TAPS[order][0] == order
    period = 2**order - 1
    assert _gf2_powmod_x(period, poly, order) == 1
    for q in _prime_factors(period):
        assert _gf2_powmod_x(period // q, poly, order) != 1


@pytest.mark.parametrize("order", [o for o in sorted(PRBS_TAPS) if o <= 14])
def test_prbs_maximum_length_and_balance(order):
    P = 2**order - 1
    x = PrbsGenerator(amplitude_hz=0.05, seed=123, order=order).next_block(2 * P)
    np.testing.assert_array_equal(x[:P], x[P:])  # period P …
    for q in _prime_factors(P):  # … and no shorter one
        assert not np.array_equal(x[:P], np.roll(x[:P], P // q))
    assert np.count_nonzero(x[:P] > 0) == 2 ** (order - 1)  # balance: one more high than low
    assert set(np.unique(x)) == {-0.05, 0.05}
    assert x[:P].mean() == pytest.approx(0.05 / P)


def test_prbs_clock_period_and_seed_shift():
    a = PrbsGenerator(order=5, clock_samples=4, seed=0).next_block(4 * 31)
    assert np.all(a.reshape(31, 4) == a.reshape(31, 4)[:, :1])
    bits_a = a[::4]
    bits_b = PrbsGenerator(order=5, clock_samples=4, seed=9).next_block(4 * 31)[::4]
    assert not np.array_equal(bits_a, bits_b)
    assert any(np.array_equal(np.roll(bits_a, k), bits_b) for k in range(31))  # the same m-sequence


# ---- multisine --------------------------------------------------------------------------------------------

def test_multisine_default_record():
    g = MultisineGenerator()  # 900 s at 0.1 s
    x = g.next_block(g.record_samples)
    assert np.max(np.abs(x)) == pytest.approx(0.1, rel=1e-12)
    assert g.crest_factor == pytest.approx(crest_factor(x))
    equal_phase = math.sqrt(2 * len(TSO_PERIODS_S))  # all cosines peak together
    schroeder = MultisineGenerator(phases="schroeder").crest_factor
    assert g.crest_factor < schroeder < equal_phase
    assert g.crest_factor < 2.2
    for want, got in zip(TSO_PERIODS_S, g.periods_s):
        assert abs(got / want - 1) < 0.05  # rounded to the record's bins
    # all the energy is at the excited bins, i.e. at the TSO periods
    X = np.abs(np.fft.rfft(x)) ** 2
    assert X[list(g.bins)].sum() / X[1:].sum() > 0.9999
    assert X[0] / X.sum() < 1e-20
    # equal amplitudes
    amps = np.sqrt(X[list(g.bins)]) * 2 / g.record_samples
    np.testing.assert_allclose(amps, g.component_amplitude_hz, rtol=1e-9)
    np.testing.assert_allclose(x.std(), g.rms_hz, rtol=1e-9)


def test_multisine_is_periodic_and_reports_phases():
    g = small_multisine()
    x = g.next_block(3 * 600)
    np.testing.assert_array_equal(x[:600], x[600:1200])
    d = g.description
    assert d.kind == "multisine" and len(d.params["phases_rad"]) == len(TSO_PERIODS_S)
    assert d.params["crest_factor"] == g.crest_factor


def test_sine_generator():
    g = SineGenerator(amplitude_hz=0.1, sample_time_s=0.1, period_s=40.0)
    x = g.next_block(400)
    assert x[100] == pytest.approx(0.1) and x[300] == pytest.approx(-0.1)
    assert crest_factor(x) == pytest.approx(math.sqrt(2), rel=1e-6)
