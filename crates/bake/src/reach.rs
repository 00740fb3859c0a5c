//! The reach a point stores: at or above the f64 reach of its list, and far enough that the
//! GPU's expansion, which measures distances in f32 on the stored positions, keeps every
//! member of that list; stored as the half float at or above it (`GpuPoint::new`).

use slosh_cache::stored_radius;

/// How far a list member's distance in f32, on the stored positions, can lie beyond the f64
/// reach of its list, in local units: the positions lie within the unit box (recentred, then
/// at most 2 from the surface's own centre), so rounding each coordinate to f32 moves a
/// distance by at most about 2e-7, and a GPU list, measured in f32, may keep a member by as
/// much again. Five times that.
pub(crate) const REACH_SLACK: f64 = 1e-6;

/// How near its reach a list member must lie, in f64, to be measured: one farther in lies
/// more than [`REACH_SLACK`] inside the reach in f32 too, where it cannot raise the stored
/// reach. A bake's GPU search keeps only those of each list
/// (`slosh_mls::KeptLists::NearReach`). Four times the slack.
pub(crate) const NEAR_REACH_BAND: f64 = 4.0 * REACH_SLACK;

/// The smallest f32 at or above `reach` whose square is at or above the list's farthest
/// squared f32 distance, `far2` (asked only where it can matter: the f32 distances exceed
/// `reach` by at most [`REACH_SLACK`], so where the half float the point stores lies that
/// much above `reach`, they cannot pass it: at the reaches of a million-point step, some
/// three lists in four are not measured).
pub(crate) fn stored_reach(reach: f64, far2: impl FnOnce() -> f32) -> f32 {
    let measured = stored_radius(reach).is_none_or(|h| f64::from(h) < reach + REACH_SLACK);
    let far2 = if measured { far2() } else { 0.0 };
    let mut r = (reach as f32).max(far2.sqrt());
    while r * r < far2 || f64::from(r) < reach {
        r = r.next_up();
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whatever the farthest f32 distance (up to 4e-7 beyond the reach), the point
    /// stores the same half float as it would had every list been measured; and where the
    /// distance passes the half float at or above the reach, the stored one is above it.
    #[test]
    fn unmeasured_lists_store_what_measured_ones_would() {
        let always = |reach: f64, far: f32| {
            let far2 = far * far;
            let mut r = (reach as f32).max(far);
            while r * r < far2 || f64::from(r) < reach {
                r = r.next_up();
            }
            r
        };
        let half = |r: f32| stored_radius(f64::from(r)).unwrap();
        let mut raised = 0;
        for k in 0..20_000 {
            // Reaches across a few binades, some just below a half float.
            let h = f64::from(stored_radius(1e-3 * (1.0 + k as f64 * 3e-4)).unwrap());
            for below in [1e-9, 1e-7, 3e-7, 6e-7, 9e-7, h * 4e-4, 0.0] {
                let reach = h - below;
                // As far beyond the reach as the f32 distances may lie (twice the 2e-7 of
                // rounding, whatever REACH_SLACK says).
                for beyond in [-1e-7, 0.0, 1e-7, 2e-7, 3e-7, 4e-7] {
                    let far = (reach + beyond) as f32;
                    let mut asked = false;
                    let r = stored_reach(reach, || {
                        asked = true;
                        far * far
                    });
                    let want = always(reach, far);
                    assert_eq!(
                        half(r),
                        half(want),
                        "reach {reach}, far {far}: stored {} where a measured list stores {}",
                        half(r),
                        half(want)
                    );
                    assert!(f64::from(r) >= reach);
                    if half(want) > h as f32 {
                        raised += 1;
                        assert!(asked, "reach {reach}, far {far}: raised but never measured");
                    }
                }
            }
        }
        assert!(raised > 10_000, "{raised} reaches raised by their lists");
    }
}
