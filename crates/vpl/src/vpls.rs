//! Virtual point lights: generation (direct on the emitters, indirect by instant
//! radiosity), evaluation at a shading point, the exhaustive estimator and the integrator.
