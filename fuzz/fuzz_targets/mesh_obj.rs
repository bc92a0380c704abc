//! OBJ bytes into a mesh: any input is a mesh or an error, never a panic or a runaway
//! allocation.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = endofuse::geometry::mesh_io::parse_obj(data);
});
