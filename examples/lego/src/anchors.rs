//! What a user would run instead, as the model issue measured it on this machine kind (2
//! cores, one quiet period): nerfstudio 1.1.5's nerfacto on the CPU (torch 2.1.2, its
//! defaults, 4096 rays a step) on lego at 200 x 200, judged on its held-back views. These are
//! the figures, not a run of this report.

/// `(training seconds, held-out PSNR in dB)` of nerfacto on the CPU.
pub const NERFACTO_CPU: [(f64, f64); 4] = [(31.0, 8.3), (61.0, 9.1), (156.0, 11.9), (304.0, 16.4)];

/// nerfacto's peak memory (bytes) and the seconds it takes to render one 200 x 200 view.
pub const NERFACTO_PEAK_BYTES: f64 = 5.7e9;
/// See [`NERFACTO_PEAK_BYTES`].
pub const NERFACTO_RENDER_SECONDS: f64 = 30.0;
