//! Line charts for the lab and the demo, each drawn twice: SVG (text left to the viewer's
//! fonts) and PNG (text rasterised from DejaVu Sans, embedded, so that no system font is needed).
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::Context;

use plotters::coord::Shift;
use plotters::prelude::*;

/// Points of a line.
pub type Points = Vec<(f64, f64)>;

/// Ten colours told apart at a glance (the category-10 palette), none of them black, the
/// axes' colour: the first ten series of a chart each get their own.
pub const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Width of the legend column right of the plot (pixels).
const LEGEND_W: u32 = 170;

/// A tick label: whole numbers without a decimal point, others with what they need.
fn tick(v: f64) -> String {
    if (v - v.round()).abs() <= 1e-9 * v.abs().max(1.0) {
        format!("{}", v.round() as i64)
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// The range of the finite points of `series`, padded a little in y.
fn ranges(series: &[Series]) -> ((f64, f64), (f64, f64)) {
    let finite = || series.iter().flat_map(|s| s.points.iter()).filter(|(x, y)| x.is_finite() && y.is_finite());
    let (x0, x1, y0, y1) = finite()
        .fold((f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY), |(a, b, c, d), &(x, y)| {
            (a.min(x), b.max(x), c.min(y), d.max(y))
        });
    let (x0, x1) = if x0.is_finite() { (x0, x1.max(x0 + 1e-9)) } else { (0.0, 1.0) };
    let (y0, y1) = if y0.is_finite() { (y0, y1) } else { (0.0, 1.0) };
    let pad = ((y1 - y0) * 0.05).max(1e-9 + (y1.abs() * 1e-3));
    ((x0, x1), (y0 - pad, y1 + pad))
}

fn style_of(k: usize, s: &Series) -> ShapeStyle {
    let c = PALETTE[k % PALETTE.len()];
    if s.wide {
        c.mix(0.5).stroke_width(3)
    } else {
        c.stroke_width(1)
    }
}

/// The legend in its own column, so that it covers no data.
fn legend<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, series: &[Series], top: i32) -> anyhow::Result<()> {
    for (k, s) in series.iter().enumerate() {
        let y = top + 18 * k as i32;
        let style = style_of(k, s);
        area.draw(&PathElement::new([(4, y), (24, y)], style.stroke_width(style.stroke_width.max(2)))).map_err(err)?;
        area.draw(&Text::new(s.label.clone(), (30, y - 7), ("sans-serif", 13))).map_err(err)?;
    }
    Ok(())
}

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
    write_both(stem, title, x_desc, y_desc, series, false)
}

/// One panel per series, stacked, each on its own y range and all on one x range, written to
/// `stem`.svg and `stem`.png: for traces that would hide one another in a single chart.
pub fn panel_chart(stem: &Path, title: &str, x_desc: &str, y_desc: &str, series: &[Series]) -> anyhow::Result<()> {
    write_both(stem, title, x_desc, y_desc, series, true)
}

/// The chart drawn twice, SVG and PNG, overlaid or in panels.
fn write_both(stem: &Path, title: &str, x: &str, y: &str, series: &[Series], panels: bool) -> anyhow::Result<()> {
    font_registered()?;
    let with = |ext: &str| -> PathBuf {
        let mut name = stem.as_os_str().to_owned();
        name.push(ext);
        PathBuf::from(name)
    };
    let svg = with(".svg");
    draw(SVGBackend::new(&svg, SIZE).into_drawing_area(), title, x, y, series, panels)
        .with_context(|| format!("writing {}", svg.display()))?;
    let png = with(".png");
    let mut rgb = vec![0u8; SIZE.0 as usize * SIZE.1 as usize * 3];
    draw(BitMapBackend::with_buffer(&mut rgb, SIZE).into_drawing_area(), title, x, y, series, panels)
        .with_context(|| format!("drawing {}", png.display()))?;
    write_png(&png, &rgb).with_context(|| format!("writing {}", png.display()))
}

/// An RGB buffer of `SIZE` as a PNG file, through the `png` crate: plotters' own encoder goes
/// through the `image` crate and its JPEG, BMP and GIF codecs, a tenth of the binary's build.
fn write_png(path: &Path, rgb: &[u8]) -> anyhow::Result<()> {
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut enc = png::Encoder::new(file, SIZE.0, SIZE.1);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header()?;
    w.write_image_data(rgb)?;
    w.finish()?;
    Ok(())
}

/// The chart: every series on one plot, or (`panels`) each on its own plot, stacked, on its
/// own y range and the common x range; the legend in its own column right of them.
fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    series: &[Series],
    panels: bool,
) -> anyhow::Result<()> {
    let ((x0, x1), y_all) = ranges(series);
    root.fill(&WHITE).map_err(err)?;
    let root = root.titled(title, ("sans-serif", 18)).map_err(err)?;
    let (plots, key) = root.split_horizontally(SIZE.0 - LEGEND_W);
    let indexed: Vec<(usize, &Series)> = series.iter().enumerate().collect();
    let groups: Vec<&[(usize, &Series)]> = if panels { indexed.chunks(1).collect() } else { vec![&indexed[..]] };
    let n = groups.len().max(1);
    for (g, (group, area)) in groups.iter().zip(plots.split_evenly((n, 1))).enumerate() {
        let (y0, y1) = if panels { ranges(std::slice::from_ref(group[0].1)).1 } else { y_all };
        let last = g + 1 == n;
        let mut chart = ChartBuilder::on(&area)
            .margin(if panels { 4 } else { 10 })
            .x_label_area_size(if last { 35 } else { 0 })
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(err)?;
        let mut mesh = chart.configure_mesh();
        mesh.y_desc(y_desc).x_label_formatter(&|v| tick(*v)).y_label_formatter(&|v| tick(*v));
        if panels {
            mesh.y_labels(4);
        }
        if last {
            mesh.x_desc(x_desc);
        }
        mesh.draw().map_err(err)?;
        for &(k, s) in group.iter() {
            let pts = s.points.iter().copied().filter(|(x, y)| x.is_finite() && y.is_finite());
            chart.draw_series(LineSeries::new(pts, style_of(k, s))).map_err(err)?;
        }
    }
    legend(&key, series, 20)?;
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

    /// Seven methods (the demo's) are seven colours, none of them black, and the legend sits
    /// right of the plot, where no data is.
    #[test]
    fn every_series_has_its_own_colour_and_the_legend_covers_no_data() {
        font_registered().unwrap();
        let series: Vec<Series> =
            (0..7).map(|k| Series::new(format!("m{k}"), (0..100).map(|x| (x as f64, k as f64)).collect())).collect();
        let (w, h) = SIZE;
        let mut buf = vec![0u8; (w * h * 3) as usize];
        draw(BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area(), "t", "x", "y", &series, false).unwrap();
        let count = |c: RGBColor, xs: std::ops::Range<u32>| {
            (0..h)
                .flat_map(|y| xs.clone().map(move |x| ((y * w + x) * 3) as usize))
                .filter(|&i| buf[i] == c.0 && buf[i + 1] == c.1 && buf[i + 2] == c.2)
                .count()
        };
        let plot = 0..w - LEGEND_W;
        for (k, c) in PALETTE.iter().take(7).enumerate() {
            assert!(count(*c, plot.clone()) > 200, "series {k} not drawn in its colour");
            assert!(count(*c, w - LEGEND_W..w) > 0, "series {k} not in the legend");
        }
        assert!(PALETTE.iter().all(|c| c.0 as u32 + c.1 as u32 + c.2 as u32 > 150), "a colour too near black");
    }

    #[test]
    fn ticks_show_whole_numbers_without_a_point() {
        assert_eq!(tick(10000.0), "10000");
        assert_eq!(tick(-2.0), "-2");
        assert_eq!(tick(0.25), "0.25");
        assert_eq!(tick(0.125), "0.125");
    }

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
