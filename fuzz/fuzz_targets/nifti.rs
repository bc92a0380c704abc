//! NIfTI-1 label volumes, plain and gzipped (the first byte picks which): a header that claims
//! a 10⁹-voxel volume must not allocate it.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Some((&pick, rest)) = data.split_first() else {
        return;
    };
    let name = if pick & 1 == 0 { "labels.nii" } else { "labels.nii.gz" };
    let _ = endofuse::ctimport::volume::read_bytes(std::path::Path::new(name), rest);
});
