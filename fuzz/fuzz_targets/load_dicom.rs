#![no_main]
//! DICOM files of any shape: the loader must return Ok or Err, never panic or over-allocate.
mod common;
use libfuzzer_sys::fuzz_target;

#[global_allocator]
static ALLOCATOR: voyage_io::GuardedAllocator = voyage_io::GuardedAllocator;

fuzz_target!(|data: &[u8]| {
    common::load_as("input.dcm", data);
});
