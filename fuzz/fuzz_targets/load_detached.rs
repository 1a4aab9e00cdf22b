#![no_main]
//! MetaImage (.mhd) and NRRD (.nhdr) headers whose voxels lie in a file beside them: the
//! header, then (after the first NUL byte) the bytes of `data.raw` in the same folder. The
//! first byte picks the format. A header may name any file; the loader must read only a
//! regular file inside the header's folder, and never hang or run out of memory.
mod common;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, body)) = data.split_first() else { return };
    let (header, raw) = match body.iter().position(|&b| b == 0) {
        Some(i) => (&body[..i], &body[i + 1..]),
        None => (body, &[][..]),
    };
    common::save_as("data.raw", raw);
    common::load_as(if pick & 1 == 0 { "input.mhd" } else { "input.nhdr" }, header);
});
