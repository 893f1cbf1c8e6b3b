//! A minimal SVG writer: markup is written by hand into one `String`, coordinates as compact
//! numbers (at most one decimal, in the picture's own pixel space) and text escaped for XML.

use std::fmt::Write;

/// Largest coordinate magnitude written; anything beyond (or not finite) is clamped, so the output
/// never holds `NaN`, `inf` or numbers a viewer chokes on.
const MAX_COORD: f64 = 1e6;

/// An SVG document being written.
pub(super) struct Svg {
    out: String,
}

impl Svg {
    /// Opens a `width` x `height` document with a white background, the accessible `<title>`
    /// and the shared text defaults (inherited by every `<text>`).
    pub fn new(width: f64, height: f64, title: &str, capacity: usize) -> Svg {
        let mut svg = Svg {
            out: String::with_capacity(capacity),
        };
        svg.raw(r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 "#);
        svg.num(width);
        svg.raw(" ");
        svg.num(height);
        svg.raw(r#"" width=""#);
        svg.num(width);
        svg.raw(r#"" height=""#);
        svg.num(height);
        svg.raw(
            r##"" role="img" font-family="system-ui,-apple-system,'Segoe UI',Roboto,Helvetica,Arial,sans-serif" font-size="13" fill="#1a1a1a"><title>"##,
        );
        svg.text(title);
        svg.raw("</title>\n");
        svg.raw(r##"<rect width="100%" height="100%" fill="#fff"/>"##);
        svg.raw("\n");
        svg
    }

    /// Closes the document and returns it.
    pub fn finish(mut self) -> String {
        self.out.push_str("</svg>\n");
        self.out
    }

    /// Appends markup as is (callers pass literals only).
    pub fn raw(&mut self, s: &str) {
        self.out.push_str(s);
    }

    /// Appends a coordinate: rounded to one decimal, trailing `.0` dropped, never `-0`,
    /// clamped to +-1e6, 0 for a value that is not finite.
    pub fn num(&mut self, v: f64) {
        push_num(&mut self.out, v);
    }

    /// Appends `" name="value"` for a coordinate attribute (a leading space included).
    pub fn attr(&mut self, name: &str, v: f64) {
        self.out.push(' ');
        self.out.push_str(name);
        self.out.push_str("=\"");
        push_num(&mut self.out, v);
        self.out.push('"');
    }

    /// Appends text (content or attribute value) escaped for XML: `& < > " '` become entities and
    /// characters XML 1.0 does not allow (control characters) are dropped.
    pub fn text(&mut self, s: &str) {
        for c in s.chars() {
            match c {
                '&' => self.out.push_str("&amp;"),
                '<' => self.out.push_str("&lt;"),
                '>' => self.out.push_str("&gt;"),
                '"' => self.out.push_str("&quot;"),
                '\'' => self.out.push_str("&#39;"),
                '\t' | '\n' | '\r' => self.out.push(' '),
                c if (c as u32) < 0x20 || c == '\u{FFFE}' || c == '\u{FFFF}' => {}
                c => self.out.push(c),
            }
        }
    }

    /// A `<text>` element at (x, y). `anchor` is `start`, `middle` or `end`; `extra` holds
    /// further literal attributes (e.g. `font-weight="600"`), with a leading space, or "".
    pub fn label(&mut self, x: f64, y: f64, anchor: &str, extra: &str, content: &str) {
        self.raw("<text");
        self.attr("x", x);
        self.attr("y", y);
        if anchor != "start" {
            self.raw(" text-anchor=\"");
            self.raw(anchor);
            self.raw("\"");
        }
        self.raw(extra);
        self.raw(">");
        self.text(content);
        self.raw("</text>\n");
    }

    /// A straight segment; `style` holds literal attributes with a leading space.
    pub fn line(&mut self, (x1, y1): (f64, f64), (x2, y2): (f64, f64), style: &str) {
        self.raw("<line");
        self.attr("x1", x1);
        self.attr("y1", y1);
        self.attr("x2", x2);
        self.attr("y2", y2);
        self.raw(style);
        self.raw("/>");
    }

    /// A rectangle; `style` holds literal attributes with a leading space.
    pub fn rect(&mut self, r: Rect, style: &str) {
        self.raw("<rect");
        self.attr("x", r.x);
        self.attr("y", r.y);
        self.attr("width", r.w);
        self.attr("height", r.h);
        self.raw(style);
        self.raw("/>");
    }

    /// A polyline through `points` (nothing for fewer than two); `style` as for [`Svg::line`].
    pub fn polyline(&mut self, points: impl IntoIterator<Item = (f64, f64)>, style: &str) {
        let start = self.out.len();
        self.raw("<polyline points=\"");
        let mut count = 0;
        for (x, y) in points {
            if count > 0 {
                self.out.push(' ');
            }
            push_num(&mut self.out, x);
            self.out.push(',');
            push_num(&mut self.out, y);
            count += 1;
        }
        if count < 2 {
            self.out.truncate(start);
            return;
        }
        self.raw("\"");
        self.raw(style);
        self.raw("/>");
    }

    /// Appends formatted markup (for the rare attribute that is neither a coordinate nor text).
    pub fn fmt(&mut self, args: std::fmt::Arguments) {
        let _ = self.out.write_fmt(args);
    }
}

/// A rectangle in picture pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Rect {
    pub x: f64,
    pub y: f64,
    pub w: f64,
    pub h: f64,
}

impl Rect {
    pub fn right(&self) -> f64 {
        self.x + self.w
    }
    pub fn bottom(&self) -> f64 {
        self.y + self.h
    }
}

/// Writes `v` rounded to one decimal (see [`Svg::num`]).
fn push_num(out: &mut String, v: f64) {
    let v = if v.is_finite() {
        v.clamp(-MAX_COORD, MAX_COORD)
    } else {
        0.0
    };
    let tenths = (v * 10.0).round() as i64;
    if tenths < 0 {
        out.push('-');
    }
    let a = tenths.unsigned_abs();
    let _ = write!(out, "{}", a / 10);
    let f = (a % 10) as u8;
    if f != 0 {
        out.push('.');
        out.push(char::from(b'0' + f));
    }
}

/// A value for a human (tick or axis label): up to four significant digits, trailing zeros
/// dropped, scientific notation beyond 1e5 or below 1e-3; "–" for a value that is not finite.
pub(super) fn human(v: f64) -> String {
    if !v.is_finite() {
        return "–".into();
    }
    let a = v.abs();
    if a == 0.0 {
        return "0".into();
    }
    if !(1e-3..1e5).contains(&a) {
        return format!("{v:.1e}");
    }
    let decimals = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
    trim(format!("{v:.decimals$}"))
}

/// `v` with `decimals` decimals, trailing zeros (and a bare point) dropped, never `-0`.
pub(super) fn fixed(v: f64, decimals: usize) -> String {
    if !v.is_finite() {
        return "–".into();
    }
    trim(format!("{v:.decimals$}"))
}

fn trim(s: String) -> String {
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" { "0".into() } else { s }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn num(v: f64) -> String {
        let mut s = String::new();
        push_num(&mut s, v);
        s
    }

    #[test]
    fn numbers_are_compact_and_finite() {
        assert_eq!(num(12.0), "12");
        assert_eq!(num(12.34), "12.3");
        assert_eq!(num(-0.04), "0");
        assert_eq!(num(-0.06), "-0.1");
        assert_eq!(num(f64::NAN), "0");
        assert_eq!(num(f64::INFINITY), "0");
        assert_eq!(num(1e300), "1000000");
    }

    #[test]
    fn human_values() {
        assert_eq!(human(0.0), "0");
        assert_eq!(human(0.25), "0.25");
        assert_eq!(human(1234.5678), "1235");
        assert_eq!(human(3.0), "3");
        assert_eq!(human(-0.5), "-0.5");
        assert_eq!(human(2e7), "2.0e7");
        assert_eq!(human(f64::NAN), "–");
        assert_eq!(fixed(-0.0001, 2), "0");
        assert_eq!(fixed(0.5, 2), "0.5");
    }

    #[test]
    fn text_is_escaped() {
        let mut s = Svg { out: String::new() };
        s.text("a<b & \"c\" 'd'>\u{1}\n");
        assert_eq!(s.out, "a&lt;b &amp; &quot;c&quot; &#39;d&#39;&gt; ");
    }
}
