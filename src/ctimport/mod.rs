//! CT label volumes to meshes (placeholder: being written).
