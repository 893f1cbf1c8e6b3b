//! Colours: a colour-blind-safe palette for structures (Okabe and Ito's hues, the orange
//! darkened, completed with wine and violet) whose every colour has at least 3:1 contrast
//! against the white background (WCAG's bar for graphics), grey for outliers, and text colours
//! of at least 4.5:1.

/// Structure colours, by label (cycled past the eighth).
pub const STRUCTURES: [&str; 8] = [
    "#0072b2", // blue
    "#d55e00", // vermillion
    "#009e73", // bluish green
    "#cc79a7", // reddish purple
    "#b07800", // dark orange
    "#000000", // black
    "#882255", // wine
    "#6a3d9a", // violet
];

/// Outliers (label -1).
pub const OUTLIER: &str = "#8c8c8c";
/// Body text.
pub const TEXT: &str = "#1a1a1a";
/// Secondary text (axis labels, notes).
pub const MUTED: &str = "#555555";
/// Frames, axes and grid.
pub const RULE: &str = "#c8c8c8";

/// The colour of a label: grey for a negative label, otherwise the palette's colour.
pub fn colour(label: i64) -> &'static str {
    match usize::try_from(label) {
        Ok(l) => STRUCTURES[l % STRUCTURES.len()],
        Err(_) => OUTLIER,
    }
}

#[cfg(test)]
/// WCAG 2 contrast ratio of two `#rrggbb` colours (1 to 21).
pub fn contrast(a: &str, b: &str) -> f64 {
    let (la, lb) = (luminance(a), luminance(b));
    (la.max(lb) + 0.05) / (la.min(lb) + 0.05)
}

#[cfg(test)]
/// WCAG 2 relative luminance of a `#rrggbb` colour (0 for anything else).
fn luminance(hex: &str) -> f64 {
    let channel = |i: usize| {
        let v = hex
            .get(i..i + 2)
            .and_then(|h| u8::from_str_radix(h, 16).ok())
            .map_or(0.0, |v| f64::from(v) / 255.0);
        if v <= 0.03928 {
            v / 12.92
        } else {
            ((v + 0.055) / 1.055).powf(2.4)
        }
    };
    0.2126 * channel(1) + 0.7152 * channel(3) + 0.0722 * channel(5)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_have_enough_contrast_on_white() {
        for c in STRUCTURES.iter().chain([&OUTLIER, &RULE]) {
            if *c != RULE {
                assert!(
                    contrast(c, "#ffffff") >= 3.0,
                    "{c}: {}",
                    contrast(c, "#ffffff")
                );
            }
        }
        assert!(contrast(TEXT, "#ffffff") >= 4.5);
        assert!(contrast(MUTED, "#ffffff") >= 4.5);
    }

    #[test]
    fn outliers_are_grey_and_labels_cycle() {
        assert_eq!(colour(-1), OUTLIER);
        assert_eq!(colour(-7), OUTLIER);
        assert_eq!(colour(0), STRUCTURES[0]);
        assert_eq!(colour(8), STRUCTURES[0]);
        assert!((contrast("#000000", "#ffffff") - 21.0).abs() < 1e-9);
    }
}
