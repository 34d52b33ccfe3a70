"""A record too long for memory is refused with the sizes before anything is allocated
(numpy's bare MemoryError, or the kernel's OOM killer, otherwise)."""
import numpy as np
import pytest

from estimators import EKF, discretize
from fmu_models import get_model
from fmu_models.errors import ResourceError


@pytest.mark.parametrize("keep", ["all", "estimates"])
def test_a_run_over_a_record_too_long_for_memory_is_a_resource_error(keep):
    f = EKF(discretize(get_model("cartpole"), 0.01), [0.5, 0, 1.8, 0.5], 1.0, 0.1, 0.1)
    n = 10**10                                       # views: the record itself takes no memory
    us, ys = np.broadcast_to(np.zeros(1), (n, 1)), np.broadcast_to(np.zeros(2), (n, 2))
    x_before = f.x
    with pytest.raises(ResourceError, match=r"EKF: run over N = 10000000000 steps \(\d+ bytes a step\) needs "
                                            r"[\d.]+ GiB.*filter the record in pieces"):
        f.run(us, ys, keep=keep)
    np.testing.assert_array_equal(f.x, x_before)       # the filter is where it was
    assert f.run(np.zeros((10, 1)), np.zeros((10, 2)), keep=keep).x.shape == (11, 4)
