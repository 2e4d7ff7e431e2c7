"""detect.nearest gives scipy's answers (distance_transform_edt's labels, cKDTree's k nearest)"""

import numpy as np
import pytest

scipy_ndimage = pytest.importorskip("scipy.ndimage")
cKDTree = pytest.importorskip("scipy.spatial").cKDTree

from rotstar_mrcal.detect.nearest import knn_third_party, nearest_label  # noqa: E402


def blobs(seed, shape=(90, 120), n=40):
    """A label image of n random rectangles (some touching), 0 elsewhere"""
    rng = np.random.default_rng(seed)
    lab = np.zeros(shape, np.int32)
    for k in range(1, n + 1):
        y, x = rng.integers(0, shape[0] - 3), rng.integers(0, shape[1] - 3)
        lab[y:y + rng.integers(1, 8), x:x + rng.integers(1, 8)] = k
    return lab


def scipy_label(lab, max_dist):
    dist, (iy, ix) = scipy_ndimage.distance_transform_edt(lab == 0, return_indices=True)
    vor = lab[iy, ix]
    vor[dist > max_dist] = 0
    return vor


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("max_dist", [2.5, 6.0, 1e9])
def test_nearest_label_is_scipys(seed, max_dist):
    lab = blobs(seed)
    np.testing.assert_array_equal(nearest_label(lab, max_dist), scipy_label(lab, max_dist))


def test_nearest_label_ties_and_empty_columns():
    lab = np.zeros((7, 11), np.int32)
    lab[0, 0], lab[6, 0], lab[3, 10], lab[0, 6] = 1, 2, 3, 4  # many equidistant pixels
    np.testing.assert_array_equal(nearest_label(lab, 20.0), scipy_label(lab, 20.0))


def kdtree_keep(points, owner, p, a, b, k=24, ratio=1.25):
    dd, ii = cKDTree(points).query(p, k=k)
    own = owner[ii]
    d_ab = np.where((own == a[:, None]) | (own == b[:, None]), dd, np.inf).min(axis=1)
    d_3 = np.where((own != a[:, None]) & (own != b[:, None]), dd, np.inf).min(axis=1)
    return d_3 > ratio * d_ab


@pytest.mark.parametrize("seed", range(4))
def test_knn_third_party_is_the_kdtree_answer(seed):
    """Contour points of random rectangles; queries on the Voronoi boundaries, as contact_graph makes them"""
    import cv2

    lab = blobs(seed, (120, 160), 60)
    contours, owner = [], []
    for k in range(1, lab.max() + 1):
        cs, _ = cv2.findContours((lab == k).astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        for c in cs:
            contours.append(c[:, 0, :])
            owner.append(np.full(len(c), k - 1))
    pts, owner = np.concatenate(contours), np.concatenate(owner)
    vor = scipy_label(lab, 8.0)
    ya, xa = np.nonzero((vor[:, :-1] != vor[:, 1:]) & (vor[:, :-1] > 0) & (vor[:, 1:] > 0))
    yb, xb = np.nonzero((vor[:-1, :] != vor[1:, :]) & (vor[:-1, :] > 0) & (vor[1:, :] > 0))
    a = np.concatenate((vor[ya, xa], vor[yb, xb])) - 1
    b = np.concatenate((vor[ya, xa + 1], vor[yb + 1, xb])) - 1
    p = np.concatenate((np.column_stack((xa + 0.5, ya)), np.column_stack((xb, yb + 0.5))))
    keep, undecided = knn_third_party(pts, owner, p, a, b)
    ref = kdtree_keep(pts, owner, p, a, b)
    assert len(p) > 500 and undecided.mean() < 0.05
    np.testing.assert_array_equal(keep[~undecided], ref[~undecided])


def test_knn_third_party_leaves_open_ties_to_the_caller():
    """The k-th nearest is one of two equally far points, of a and of a third element c: open"""
    q = np.array([[0.5, 0.0]])
    pts = [(0, 0)] + [(x, 5) for x in range(-11, 12)]  # a: 24 points within 12.5 px
    pts += [(-12, 10), (13, 10)]  # 16 px from q, mirror images: the 25th nearest is either
    pts = np.array(pts)
    owner = np.array([0] * 24 + [0, 2])
    keep, undecided = knn_third_party(pts, owner, q, np.array([0]), np.array([1]), k=25, ratio=200.0)
    assert undecided.tolist() == [True]
    # with c's point nearer (inside the 25), the answer is settled: c is within 200 x 0.5 px
    pts[-1] = (13, 9)
    keep, undecided = knn_third_party(pts, owner, q, np.array([0]), np.array([1]), k=25, ratio=200.0)
    assert undecided.tolist() == [False] and keep.tolist() == kdtree_keep(pts, owner, q, np.array([0]),
                                                                          np.array([1]), k=25, ratio=200.0).tolist()
