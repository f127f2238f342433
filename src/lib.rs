pub use fogray_ops as ops;
pub use fogray_tape as tape;
