//! An opaque RGBA image made on the CPU for a panel the window shows pixel for pixel (the
//! scout, the CT slices). It names no window toolkit, so the view logic that draws the
//! panels lives here, beside the other CPU renderers, and the window only uploads the bytes.

/// RGBA pixels, 4 bytes each, rows top to bottom, opaque, display values.
#[derive(Clone, Debug, PartialEq)]
pub struct Rgba {
    pub size: [usize; 2],
    pub bytes: Vec<u8>,
}
