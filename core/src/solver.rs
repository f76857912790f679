//! The least-squares solver's outcome in words, for reports and JSON (the crate's reason is an
//! enum whose debug form is not for people).

/// Why the solver stopped, in words for reports and JSON.
pub fn termination_words(t: &levenberg_marquardt::TerminationReason) -> String {
    use levenberg_marquardt::TerminationReason as T;
    match t {
        T::Converged { ftol: true, xtol: true } => "converged (cost and step both below tolerance)".into(),
        T::Converged { ftol: true, .. } => "converged (cost change below tolerance)".into(),
        T::Converged { .. } => "converged (step below tolerance)".into(),
        T::ResidualsZero => "converged (residuals zero)".into(),
        T::Orthogonal => "converged (residuals orthogonal to the Jacobian)".into(),
        T::LostPatience => "stopped: evaluation limit reached".into(),
        T::NoImprovementPossible(why) => format!("stopped: no improvement possible ({why})"),
        T::Numerical(why) => format!("stopped: numerical failure ({why})"),
        T::User(why) => format!("stopped: {why}"),
        T::NoParameters => "nothing to fit: no free parameter".into(),
        T::NoResiduals => "nothing to fit: no observation".into(),
        T::WrongDimensions(why) => format!("stopped: wrong dimensions ({why})"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use levenberg_marquardt::TerminationReason as T;

    #[test]
    fn every_reason_reads_as_words() {
        let all = [
            T::Converged { ftol: false, xtol: true },
            T::Converged { ftol: true, xtol: false },
            T::Converged { ftol: true, xtol: true },
            T::ResidualsZero,
            T::Orthogonal,
            T::LostPatience,
            T::NoImprovementPossible("gtol"),
            T::Numerical("jacobian"),
            T::User("stop"),
            T::NoParameters,
            T::NoResiduals,
            T::WrongDimensions("jacobian"),
        ];
        for t in all {
            let w = termination_words(&t);
            assert!(!w.contains('{') && !w.contains("ftol"), "{w}");
            assert_eq!(w.starts_with("converged"), t.was_successful(), "{w}");
        }
    }
}
