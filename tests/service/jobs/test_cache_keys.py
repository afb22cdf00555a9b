"""Result-cache keys: what changes a result changes the key, nothing else does."""

from __future__ import annotations

import base64
import struct

import numpy as np

from finaldrive.engine.api import SimSettings
from finaldrive.engine.model.road import Road
from finaldrive.engine.vehicle import Vehicle, default_vehicle
from finaldrive.service.db.results import key_hash, key_hashes
from finaldrive.service.jobs.cache import context_digest, design_keys

ROW = np.array([[0.0, 0.1, 0.09]])


def key(
    design: np.ndarray = ROW, road: Road | None = None, settings: SimSettings | None = None,
    vehicle: Vehicle | None = None, engine: str = "1",
) -> str:
    context = context_digest(road or Road("flat"), settings or SimSettings(), vehicle, engine)
    return design_keys(context, design)[0]


def test_inputs_that_change_results_change_the_key() -> None:
    base = key()
    assert key(design=ROW + np.array([[0, 0, 1e-6]])) != base
    assert key(road=Road.parse("sine:0.01:2")) != base
    assert key(settings=SimSettings(duration=1.0)) != base
    assert key(engine="2") != base
    first, value = default_vehicle().values[0]
    assert key(vehicle=default_vehicle().replace(**{first: value * 1.01})) != base
    assert key(vehicle=default_vehicle()) == base  # None means the default vehicle


def test_output_options_rounding_and_signed_zero_do_not() -> None:
    base = key()
    assert key(design=np.array([[-0.0, 0.1 + 1e-15, 0.09]])) == base
    assert key(settings=SimSettings(series=True)) == base
    # series rows come from dense output, so the stride does not move the steps; the wall-time
    # limit only decides whether a run finishes, never what it returns
    assert key(settings=SimSettings(series_stride=5)) == base
    assert key(settings=SimSettings(max_wall_s=1.0)) == base


def test_profiles_are_keyed_by_their_points() -> None:
    a = Road.from_points([0, 1, 2], [0, 0.01, 0], name="p")
    b = Road.from_points([0, 1, 2], [0, 0.02, 0], name="p")
    assert a.spec == b.spec and key(road=a) != key(road=b)


def test_a_key_holds_the_rounded_design_exactly() -> None:
    """The key's last 32 characters are the design's float64 bits: designs 1e-11 apart (above the
    rounding) have keys of their own, and the design reads back from its key."""
    designs = np.array([[0.3, 0.1, 0.09], [0.3, 0.1 + 1e-11, 0.09], [0.3 + 1e-11, 0.1, 0.09]])
    keys = design_keys(context_digest(Road("flat"), SimSettings(), None, "1"), designs)
    assert len(set(keys)) == 3 and all(len(k) == 64 for k in keys)
    assert len({k[:32] for k in keys}) == 1 and int(keys[0][:32], 16) >= 0
    for k, design in zip(keys, designs, strict=True):
        assert struct.unpack(">3d", base64.b64decode(k[32:], validate=True)) == tuple(np.round(design, 12))


def _murmur_finaliser(h: int) -> int:
    """MurmurHash3's fmix64 on Python's integers (its published constants), the oracle of the vectorised hash."""
    mask = (1 << 64) - 1
    h ^= h >> 33
    h = (h * 0xFF51AFD7ED558CCD) & mask
    h ^= h >> 33
    h = (h * 0xC4CEB9FE1A85EC53) & mask
    return h ^ (h >> 33)


def test_the_indexed_hash_mixes_every_word_of_the_key() -> None:
    """The hash is fmix64 chained over the key's five words from the last, its top 60 bits; keys that
    share their context (every key of a job's road) spread over the index, as a hash of the context's
    digits alone would not."""
    context = context_digest(Road("flat"), SimSettings(), None, "1")
    grid = np.array([[a, l, r] for a in (0.0, 0.1) for l in np.linspace(0, 0.1, 50) for r in (0.09, 0.1)])
    keys = design_keys(context, grid)
    for k in keys[:20]:
        words = [int(k[:16], 16), int(k[16:32], 16), *struct.unpack(">3Q", base64.b64decode(k[32:]))]
        h = 0
        for word in reversed(words):
            h = _murmur_finaliser(h ^ word)
        assert key_hash(k) == h >> 4
    hashes = key_hashes(keys)
    assert len(set(hashes.tolist())) == len(keys)
    assert hashes.min() >= 0 and hashes.max() < 2 ** 60
    assert np.unique(hashes >> 52).size > 100   # the top bits spread too (200 keys over 256 values)
