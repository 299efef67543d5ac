//! Pictures a person looks at: DEM hillshade, elevation and slope maps with colour bars
//! ([`render`]), the paper's Fig. 7 match picture ([`matchplot`]) and line plots ([`plot`]).

pub mod matchplot;
pub mod plot;
pub mod render;
