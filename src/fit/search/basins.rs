//! Distinct basins: which candidates of one cloud count as different answers, so that
//! the candidates a round keeps are that many answers, not one answer several times.

use super::*;

/// a4 from which a shape counts as having a hole when finalists are picked
pub(super) const SOME_HOLE: f64 = 0.5;

/// Two candidates whose heights along the axis (a3) differ by more than this factor lie
/// in distinct basins (`distinct_basin`). Seen face-on, a thin washer and a thick body
/// behind its face both fit the visible face, and after round 1's few steps the thick
/// one often scores better; counted as one basin, it took the washer's place in round 2.
/// With `search::ROUND1_KEPT` at 5, interleaved on fresh seeds: broadened views +14 of
/// 640 (4250000-4280000, 4360000-4390000; thin washers most) at 3-5% more time; the
/// suite's fifteen sets 2612 -> 2622 of 2700 (`docs/fit.md`).
pub const DISTINCT_THICKNESS: f64 = 2.0;

/// Two candidates in different basins of the fit: one with a hole and one without,
/// heights along the axis (a3) more than [`DISTINCT_THICKNESS`] times apart, hole axes
/// more than 10 degrees apart, or in-plane turns more than 20 degrees apart modulo the
/// quarter turn (a squarish top view and its 45-degree-turned diamond are the classic
/// pair).
pub(super) fn distinct_basin(a: &Candidate, b: &Candidate) -> bool {
    // a body with a hole and one without: a pot's wall is fitted by a thick ring as well
    // as by a closed cylinder, and the hole preference of stage 2 must see both
    if (a.shape.a4 >= SOME_HOLE) != (b.shape.a4 >= SOME_HOLE) {
        return true;
    }
    // a thin washer and a thick body whose face is the washer's (the sensor sees one face
    // of either) share axis and turn, and least squares takes the one for the other
    let (thin, thick) = (a.shape.a3.min(b.shape.a3), a.shape.a3.max(b.shape.a3));
    if thick > DISTINCT_THICKNESS * thin {
        return true;
    }
    let (a, b) = (&a.pose, &b.pose);
    if a.axis().dot(b.axis()).abs() < 10f64.to_radians().cos() {
        return true;
    }
    let x = b.rotation.inverse() * (a.rotation * DVec3::X);
    let turn = x.y.atan2(x.x).rem_euclid(std::f64::consts::FRAC_PI_2);
    let turn = turn.min(std::f64::consts::FRAC_PI_2 - turn);
    turn > 20f64.to_radians()
}

/// The best `keep` of one cloud's candidates in distinct basins, most likely first.
pub(super) fn most_likely_distinct(mut candidates: Vec<Scored>, keep: usize) -> Vec<Scored> {
    candidates.sort_by(|a, b| a.rank(b));
    let mut kept: Vec<Scored> = Vec::new();
    for c in candidates {
        if kept.len() == keep {
            break;
        }
        if kept
            .iter()
            .all(|k| distinct_basin(&k.candidate, &c.candidate))
        {
            kept.push(c);
        }
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_thin_washer_and_a_thick_body_on_one_axis_are_distinct_basins() {
        let with_height = |a3: f64| Candidate {
            shape: Shape::new(0.2, 0.1, a3, 2.0, 1.0, 1.0),
            pose: Pose::new(DQuat::IDENTITY, DVec3::ZERO),
        };
        let washer = with_height(0.02);
        assert!(distinct_basin(&washer, &with_height(0.02 * 2.5)));
        assert!(distinct_basin(&with_height(0.3), &washer));
        // heights within the factor: one basin (same axis, turn and hole)
        assert!(!distinct_basin(&washer, &with_height(0.02 * 1.5)));
    }
}
