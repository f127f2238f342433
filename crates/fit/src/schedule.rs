//! The training loop's schedules over the budget: the learning rate's anneal and the grid's
//! coarse-to-fine growth, both as functions of the fraction of the budget spent (so that a fit
//! of seconds and a fit of steps follow the same shape).

use crate::settings::FitSettings;

/// The fraction of the budget from which the learning rate anneals from `lr` to `lr_final`.
/// Adam at a constant rate keeps the grid jittering about its fit; shrinking the steps over
/// the last part settles it.
pub(crate) const ANNEAL_START: f64 = 0.6;

/// Fractions of the budget at which a growing grid doubles its nodes per axis.
pub(crate) const GROWTH: [f64; 2] = [0.1, 0.3];

/// Adam's learning rate at `fraction` of the budget: `lr` until [`ANNEAL_START`], then
/// geometric to `lr_final` at the end.
pub(crate) fn learning_rate(settings: &FitSettings, fraction: f64) -> f64 {
    if fraction <= ANNEAL_START {
        return settings.lr;
    }
    let u = ((fraction - ANNEAL_START) / (1.0 - ANNEAL_START)).min(1.0);
    settings.lr * (settings.lr_final / settings.lr).powf(u)
}

/// The grid's nodes per axis from each fraction of the budget on: a quarter, a half and all
/// of `grid` at 0 and [`GROWTH`] for a growing fit of at least 8 nodes, else `grid` throughout.
pub(crate) fn growth_stages(settings: &FitSettings) -> Vec<(f64, usize)> {
    let n = settings.grid;
    if !settings.grow || n < 8 {
        return vec![(0.0, n)];
    }
    vec![(0.0, n.div_ceil(4)), (GROWTH[0], n.div_ceil(2)), (GROWTH[1], n)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rate_anneals_geometrically_from_60_percent_and_the_grid_grows_in_three_stages() {
        let s = FitSettings {
            lr: 0.2,
            lr_final: 0.02,
            ..FitSettings::default()
        };
        assert_eq!(learning_rate(&s, 0.5), 0.2);
        // Geometric from 60 % of the budget: half way through the anneal, sqrt(0.2 * 0.02).
        assert!((learning_rate(&s, 0.8) - (0.2f64 * 0.02).sqrt()).abs() < 1e-15);
        assert_eq!(growth_stages(&s), vec![(0.0, 16), (0.1, 32), (0.3, 64)]);
    }

    #[test]
    fn the_rate_is_continuous_and_ends_at_lr_final() {
        let s = FitSettings::default();
        let just_after = learning_rate(&s, ANNEAL_START + 1e-12);
        assert!((just_after - s.lr).abs() < 1e-9);
        assert!((learning_rate(&s, 1.0) - s.lr_final).abs() < 1e-15);
        // Past the end it stays at lr_final.
        assert!((learning_rate(&s, 1.5) - s.lr_final).abs() < 1e-15);
    }

    #[test]
    fn small_or_fixed_grids_do_not_grow() {
        let fixed = FitSettings {
            grow: false,
            ..FitSettings::default()
        };
        assert_eq!(growth_stages(&fixed), vec![(0.0, 64)]);
        let small = FitSettings {
            grid: 7,
            ..FitSettings::default()
        };
        assert_eq!(growth_stages(&small), vec![(0.0, 7)]);
        // Odd sizes round up: 9 -> 3, 5, 9.
        let odd = FitSettings {
            grid: 9,
            ..FitSettings::default()
        };
        assert_eq!(growth_stages(&odd), vec![(0.0, 3), (0.1, 5), (0.3, 9)]);
    }
}
