"""The dust table's cell lookup (perception_proc.atmosphere.dust ``DustModel.cell``) against its reference,
``np.searchsorted(grid, reach, side="right") - 1`` clipped: on every grid point, either side of each by one ulp,
random ranges within and beyond the table, and the non-finite ones."""
from __future__ import annotations

import numpy as np
import pytest

from perception_proc.atmosphere.dust import DustModel, _table


@pytest.mark.parametrize("r_max", [0.0, 0.005, 7.3, 120.0])
def test_cell_is_searchsorted(r_max):
    grid, peak, at = _table(0.03, 0.001, 4e-9, 0.5, 2.0, r_max)
    model = DustModel(0.03, 0.001, 0.3, 0.5, 2.0, 1e-6, False, grid, peak, at)
    rng = np.random.default_rng(0)
    reach = np.concatenate([rng.uniform(-5.0, r_max + 10.0, 20000), grid, np.nextafter(grid, -np.inf),
                            np.nextafter(grid, np.inf), [np.nan, np.inf, -np.inf, 0.0, -0.0]])
    ref = np.clip(np.searchsorted(grid, reach, side="right") - 1, 0, len(grid) - 1)
    np.testing.assert_array_equal(model.cell(reach), ref)
