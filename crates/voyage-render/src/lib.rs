//! wgpu renderer (being written).
