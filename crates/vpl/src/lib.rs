//! Many-light rendering with importance caching (Georgiev et al. 2012; the thesis,
//! chapters 4.2 and 5): global illumination represented by virtual point lights
//! ([`vpls`]) and each pixel shaded with few shadow rays by sampling the VPLs from
//! distributions cached at sparse points of the scene ([`cache`]).

pub mod cache;
pub mod vpls;
