//! PLY bytes (ASCII, binary little and big endian) into a mesh: element counts in the header
//! are claims, not allocations.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = endofuse::geometry::mesh_io::parse_ply(data);
});
