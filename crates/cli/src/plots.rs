//! Line charts for the lab and the demo, each drawn twice: SVG (text left to the viewer's
//! fonts) and PNG (text rasterised from DejaVu Sans, embedded, so that no system font is needed).
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::Context;

use plotters::coord::Shift;
use plotters::prelude::*;

/// Points of a line.
pub type Points = Vec<(f64, f64)>;

const COLOURS: [RGBColor; 6] = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];

/// A named series of (x, y) points; non-finite points are left out.
pub struct Series {
    pub label: String,
    pub points: Points,
    /// Drawn wide and light (an "actual" under its "set-point").
    pub wide: bool,
}

impl Series {
    pub fn new(label: impl Into<String>, points: Points) -> Self {
        Series { label: label.into(), points, wide: false }
    }
}

fn err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow::anyhow!("drawing a plot: {e}")
}

/// The chart's size in pixels (the PNG's; the SVG's user units).
const SIZE: (u32, u32) = (900, 500);

/// Registers the embedded font with plotters once; PNG text is drawn with it.
fn font_registered() -> anyhow::Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular()).is_ok()
    });
    anyhow::ensure!(ok, "drawing a plot: the embedded DejaVu Sans font did not load");
    Ok(())
}

/// One chart with every series, a legend, and axes fitted to the data, written to
/// `stem`.svg and `stem`.png.
pub fn line_chart(stem: &Path, title: &str, x_desc: &str, y_desc: &str, series: &[Series]) -> anyhow::Result<()> {
    font_registered()?;
    let with = |ext: &str| -> PathBuf {
        let mut name = stem.as_os_str().to_owned();
        name.push(ext);
        PathBuf::from(name)
    };
    let svg = with(".svg");
    draw(SVGBackend::new(&svg, SIZE).into_drawing_area(), title, x_desc, y_desc, series)
        .with_context(|| format!("writing {}", svg.display()))?;
    let png = with(".png");
    draw(BitMapBackend::new(&png, SIZE).into_drawing_area(), title, x_desc, y_desc, series)
        .with_context(|| format!("writing {}", png.display()))
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    series: &[Series],
) -> anyhow::Result<()> {
    let finite = || series.iter().flat_map(|s| s.points.iter()).filter(|(x, y)| x.is_finite() && y.is_finite());
    let (x0, x1, y0, y1) = finite()
        .fold((f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY), |(a, b, c, d), &(x, y)| {
            (a.min(x), b.max(x), c.min(y), d.max(y))
        });
    let (x0, x1) = if x0.is_finite() { (x0, x1.max(x0 + 1e-9)) } else { (0.0, 1.0) };
    let (y0, y1) = if y0.is_finite() { (y0, y1) } else { (0.0, 1.0) };
    let pad = ((y1 - y0) * 0.05).max(1e-9 + (y1.abs() * 1e-3));
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))
        .map_err(err)?;
    chart.configure_mesh().x_desc(x_desc).y_desc(y_desc).draw().map_err(err)?;
    for (k, s) in series.iter().enumerate() {
        let c = COLOURS[k % COLOURS.len()];
        let style = if s.wide { c.mix(0.5).stroke_width(3) } else { c.stroke_width(1) };
        let pts = s.points.iter().copied().filter(|(x, y)| x.is_finite() && y.is_finite());
        chart
            .draw_series(LineSeries::new(pts, style))
            .map_err(err)?
            .label(s.label.clone())
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 15, y)], style));
    }
    chart.configure_series_labels().background_style(WHITE.mix(0.8)).draw().map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

/// A histogram of `samples` from `lo` to `hi` as (bin centre, share of samples in %), over at
/// most `max_bins` equal bins — whole multiples of `quantum` (the samples' resolution; 0: none)
/// centred on its grid, so that data in whole ns do not leave every other bin empty.
pub fn histogram(samples: &[f64], lo: f64, hi: f64, max_bins: usize, quantum: f64) -> Points {
    let max_bins = max_bins.max(1);
    let span = (hi - lo).max(0.0);
    let (lo, w, bins) = if quantum > 0.0 {
        let w = ((span / max_bins as f64 / quantum).ceil().max(1.0)) * quantum;
        let lo = lo - quantum / 2.0;
        (lo, w, (((hi - lo) / w) as usize + 1).min(max_bins + 1))
    } else {
        (lo, (span / max_bins as f64).max(f64::MIN_POSITIVE), max_bins)
    };
    let mut counts = vec![0u64; bins];
    for &x in samples.iter().filter(|x| x.is_finite()) {
        let b = (((x - lo) / w) as isize).clamp(0, bins as isize - 1) as usize;
        counts[b] += 1;
    }
    let n = samples.len().max(1) as f64;
    counts.iter().enumerate().map(|(b, &c)| (lo + (b as f64 + 0.5) * w, c as f64 / n * 100.0)).collect()
}

/// The mean and RMS of `samples` up to each index (Park 2020, Figures 10–11), at most `points`
/// points.
pub fn running_mean_rms(samples: &[f64], points: usize) -> (Points, Points) {
    let every = (samples.len() / points.max(1)).max(1);
    let (mut sum, mut sq) = (0.0, 0.0);
    let (mut mean, mut rms) = (Vec::new(), Vec::new());
    for (i, &x) in samples.iter().enumerate() {
        sum += x;
        sq += x * x;
        if (i + 1) % every == 0 || i + 1 == samples.len() {
            let n = (i + 1) as f64;
            mean.push((n, sum / n));
            rms.push((n, (sq / n).sqrt()));
        }
    }
    (mean, rms)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_and_running_figures() {
        let h = histogram(&[0.0, 0.1, 0.9, 0.99, 5.0, -3.0], 0.0, 1.0, 2, 0.0);
        // Out-of-range samples land in the edge bins; shares add to 100 %.
        assert_eq!(h.iter().map(|b| b.1).collect::<Vec<_>>(), vec![50.0, 50.0]);
        assert_eq!(h[0].0, 0.25);
        // Whole-ns data (µs) over a 40 ns span: 1 ns bins centred on the ns, none left empty
        // between two filled ones (100 bins of 0.4 ns would leave three of every five empty).
        let v: Vec<f64> = (0..=40).map(|k| k as f64 * 1e-3).collect();
        let h = histogram(&v, 0.0, 0.04, 100, 1e-3);
        assert_eq!(h.len(), 41);
        assert!(h.iter().all(|b| b.1 > 2.4 && b.1 < 2.5), "{h:?}");
        assert!((h[0].0 - 0.0).abs() < 1e-12 && (h[40].0 - 0.04).abs() < 1e-12);
        // A wider span: bins of whole ns, at most 100 (+1 for the half-quantum shift).
        let h = histogram(&[0.0, 1.0], 0.0, 1.0, 100, 1e-3);
        assert!(h.len() <= 101 && ((h[1].0 - h[0].0) / 1e-3 - 10.0).abs() < 1e-9, "{:?}", &h[..2]);
        let (m, r) = running_mean_rms(&[1.0, -1.0, 3.0, 1.0], 4);
        assert_eq!(m, vec![(1.0, 1.0), (2.0, 0.0), (3.0, 1.0), (4.0, 1.0)]);
        assert_eq!(r.last(), Some(&(4.0, 3.0f64.sqrt())));
    }
}
