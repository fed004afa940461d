//! Monte Carlo sampling routines (filled in by the render work).
