import numpy as np
import pytest

from volseg.metrics import (
    compare,
    contingency_table,
    directional_hamming,
    hamming_similarity,
    region_ratio,
    variation_of_information,
)


def brute_force_directional(a, b):
    total = 0
    for j in np.unique(b):
        in_j = b == j
        total += max(np.sum(in_j & (a == i)) for i in np.unique(a))
    return a.size - total


def test_hand_computed_example():
    a = np.array([0, 0, 0, 1, 1, 1, 2, 2])
    b = np.array([5, 5, 7, 7, 7, 7, 7, 9])
    # B's regions: {0,1} -> best overlap 2; {2..6} -> best 3 (A=1); {7} -> 1. D(A=>B) = 8-6.
    assert directional_hamming(a, b) == 2
    # A's regions: {0,1,2} -> 2 (B=5); {3,4,5} -> 3; {6,7} -> 1. D(B=>A) = 8-6.
    assert directional_hamming(b, a) == 2
    assert hamming_similarity(a, b) == pytest.approx(1 - 4 / 16)
    assert region_ratio(a, b) == 1.0
    assert contingency_table(a, b).toarray().tolist() == [[2, 1, 0], [0, 3, 0], [0, 1, 1]]


def test_permuted_labels_are_identical_and_similarity_is_symmetric(rng):
    a = rng.integers(0, 6, size=(7, 8, 9))
    perm = rng.permutation(6) * 10 - 17
    assert hamming_similarity(a, perm[a]) == 1.0
    assert variation_of_information(a, perm[a]) == pytest.approx(0, abs=1e-12)
    b = rng.integers(0, 4, size=a.shape)
    assert hamming_similarity(a, b) == hamming_similarity(b, a)
    assert 0 <= hamming_similarity(a, b) <= 1


def test_agrees_with_brute_force_on_random_labelings(rng):
    for _ in range(20):
        a = rng.integers(0, rng.integers(1, 6), size=50)
        b = rng.integers(0, rng.integers(1, 6), size=50)
        assert directional_hamming(a, b) == brute_force_directional(a, b)
        assert directional_hamming(b, a) == brute_force_directional(b, a)
        na, nb = len(np.unique(a)), len(np.unique(b))
        assert region_ratio(a, b) == min(na, nb) / max(na, nb)
        scores = compare(a, b)
        assert scores["directional_hamming_a_to_b"] == brute_force_directional(a, b)
        assert scores["directional_hamming_b_to_a"] == brute_force_directional(b, a)
        assert scores["hamming_similarity"] == pytest.approx(hamming_similarity(a, b), abs=1e-15)
        assert scores["region_ratio"] == region_ratio(a, b)
        assert scores["variation_of_information"] == variation_of_information(a, b)
        assert (scores["regions_a"], scores["regions_b"]) == (na, nb)


def test_metric_errors():
    with pytest.raises(ValueError, match="same shape"):
        hamming_similarity(np.zeros(3, int), np.zeros(4, int))
    with pytest.raises(ValueError, match="integer labels"):
        hamming_similarity(np.zeros(3), np.zeros(3, int))


def test_compare_over_a_mask_scores_only_those_voxels():
    from volseg.metrics import compare

    a = np.array([0, 0, 1, 1, 2, 2])
    b = np.array([5, 6, 1, 1, 2, 2])  # differs only where the mask is off
    mask = np.array([False, False, True, True, True, True])
    assert compare(a, b)["hamming_similarity"] < 1
    scores = compare(a, b, mask=mask)
    assert scores["hamming_similarity"] == 1.0 and scores["voxels"] == 4
    with pytest.raises(ValueError, match="boolean array"):
        compare(a, b, mask=mask.astype(int))


def test_region_spread_of_even_uneven_and_degenerate_cuts():
    from volseg.metrics import region_spread

    even = region_spread([10] * 8)
    assert even["largest_share"] == 0.125 and np.isclose(even["effective_regions"], 8.0)
    assert even["regions_at_least_1_percent"] == 8 and not even["degenerate"]
    specks = region_spread([9_990, *[1] * 29])          # one region of 99.7 % and specks
    assert specks["degenerate"] and specks["regions_at_least_1_percent"] == 1
    shares = np.array([9_990, *[1] * 29]) / 10_019
    assert np.isclose(specks["effective_regions"], 1 / np.sum(shares**2))
    assert np.isclose(specks["largest_share"], 9_990 / 10_019)
    two = region_spread([60, 40])                        # uneven, but two real regions
    assert two["largest_share"] == 0.6 and not two["degenerate"]
    big_background = region_spread([550, *[15] * 30])    # 55 % and 30 real regions
    assert not big_background["degenerate"]
    one = region_spread([100])                           # asked for one region: all of it
    assert one["largest_share"] == 1.0 and not one["degenerate"]
    assert region_spread([995, 5])["degenerate"]          # two regions, one a speck
    with pytest.raises(ValueError, match="sizes"):
        region_spread([])


def test_adjusted_rand_index_is_one_for_a_relabelling_and_zero_by_chance():
    from volseg.metrics import adjusted_rand_index

    rng = np.random.default_rng(0)
    a = rng.integers(0, 5, 20_000)
    assert adjusted_rand_index(a, (a + 3) % 7) == pytest.approx(1.0)
    assert abs(adjusted_rand_index(a, rng.integers(0, 5, 20_000))) < 0.01
    # Hubert and Arabie's example value, checked by hand: a 2x2 table [[2, 1], [0, 2]].
    assert adjusted_rand_index([0, 0, 0, 1, 1], [0, 0, 1, 1, 1]) == pytest.approx(1 / 6)
