//! STL bytes (ASCII or binary) into a mesh: a header that claims 4·10⁹ triangles must not
//! allocate them.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = endofuse::geometry::mesh_io::parse_stl(data);
});
