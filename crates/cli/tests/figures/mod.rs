//! A PNG figure as an independent decoder (the png crate) reads it.
use std::path::Path;

/// `path` decodes as a 900 × 500 chart whose title was drawn (dark pixels in the top rows: the
/// embedded font rasterised) and whose first series was (pixels of the palette's first colour,
/// RGB 31 119 180).
pub fn assert_chart_png(path: &Path) {
    let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut reader = png::Decoder::new(file).read_info().unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!((info.width, info.height), (900, 500), "{}", path.display());
    assert_eq!(info.bit_depth, png::BitDepth::Eight, "{}", path.display());
    let samples = info.color_type.samples();
    assert!(samples >= 3, "{}: {:?}", path.display(), info.color_type);
    let pixel = |x: usize, y: usize| {
        let i = y * info.line_size + x * samples;
        (buf[i], buf[i + 1], buf[i + 2])
    };
    let count = |rows: std::ops::Range<usize>, f: &dyn Fn((u8, u8, u8)) -> bool| {
        rows.flat_map(|y| (0..900).map(move |x| (x, y))).filter(|&(x, y)| f(pixel(x, y))).count()
    };
    let title = count(0..35, &|(r, g, b)| r < 100 && g < 100 && b < 100);
    assert!(title > 100, "{}: {title} dark pixels in the title rows", path.display());
    let near = |v: u8, want: i32| (v as i32 - want).abs() <= 25;
    let first = count(35..500, &|(r, g, b)| near(r, 31) && near(g, 119) && near(b, 180));
    assert!(first > 20, "{}: {first} pixels of the first series' colour", path.display());
}
