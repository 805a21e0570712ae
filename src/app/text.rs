//! How values are quoted in messages: numbers readable at any magnitude, and
//! user text cut to a readable length. Depends on nothing, so every reader and
//! writer of the app layer can use it without depending on another.

/// A number for a message: plain where that is short, else in exponent form
/// (1e-300 is written so, not with 300 zeros).
pub fn number(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() || (1e-5..1e12).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// A value cut to a readable length for a message.
pub fn short(s: &str) -> String {
    if s.chars().count() > 40 {
        format!("{}…", s.chars().take(40).collect::<String>())
    } else {
        s.to_string()
    }
}
