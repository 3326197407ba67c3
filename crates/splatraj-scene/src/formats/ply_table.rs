//! Any PLY file (ASCII, binary little or big endian) as named columns of numbers, element by
//! element. Header parsing and value decoding are ply-rs-bw's; this file only collects the
//! values column-wise so the Gaussian readers can address properties by name.

use std::io::{BufRead, Cursor};
use std::path::Path;

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    ElementDef, Encoding, Header, PropertyAccess, PropertyAccessResult, PropertyType, ScalarType,
};

use crate::error::{Result, SceneError};

/// The longest PLY header read: about 40 000 property lines, hundreds of times a splat file's
/// (an INRIA scene has 62 properties, one with 512-dimensional features under 600).
pub const MAX_HEADER_BYTES: usize = 1 << 20;

/// One PLY row as it is parsed: scalar values in header order (lists are skipped).
///
/// f64 holds every PLY scalar type exactly (32-bit ints included), so packed integers survive.
struct Row(Vec<f64>);

impl PropertyAccess for Row {
    fn new() -> Self {
        Row(Vec::with_capacity(64))
    }
    fn set_char(&mut self, _: &str, v: i8) -> PropertyAccessResult {
        self.0.push(v.into());
        PropertyAccessResult::Set
    }
    fn set_uchar(&mut self, _: &str, v: u8) -> PropertyAccessResult {
        self.0.push(v.into());
        PropertyAccessResult::Set
    }
    fn set_short(&mut self, _: &str, v: i16) -> PropertyAccessResult {
        self.0.push(v.into());
        PropertyAccessResult::Set
    }
    fn set_ushort(&mut self, _: &str, v: u16) -> PropertyAccessResult {
        self.0.push(v.into());
        PropertyAccessResult::Set
    }
    fn set_int(&mut self, _: &str, v: i32) -> PropertyAccessResult {
        self.0.push(v.into());
        PropertyAccessResult::Set
    }
    fn set_uint(&mut self, _: &str, v: u32) -> PropertyAccessResult {
        self.0.push(v.into());
        PropertyAccessResult::Set
    }
    fn set_float(&mut self, _: &str, v: f32) -> PropertyAccessResult {
        self.0.push(v.into());
        PropertyAccessResult::Set
    }
    fn set_double(&mut self, _: &str, v: f64) -> PropertyAccessResult {
        self.0.push(v);
        PropertyAccessResult::Set
    }
}

/// Values of one scalar property of an element.
#[derive(Debug, Clone)]
pub enum ColumnData {
    /// A `float` property.
    F32(Vec<f32>),
    /// Any other scalar type, widened losslessly.
    F64(Vec<f64>),
}

/// One scalar property of a PLY element.
#[derive(Debug, Clone)]
pub struct Column {
    /// Property name as in the header.
    pub name: String,
    /// Type declared in the header.
    pub scalar: ScalarType,
    /// One value per element.
    pub data: ColumnData,
}

impl Column {
    /// Value `i` as f32 (rounded for non-float types).
    pub fn f32(&self, i: usize) -> f32 {
        match &self.data {
            ColumnData::F32(v) => v[i],
            ColumnData::F64(v) => v[i] as f32,
        }
    }
    /// Value `i` as f64.
    pub fn f64(&self, i: usize) -> f64 {
        match &self.data {
            ColumnData::F32(v) => v[i].into(),
            ColumnData::F64(v) => v[i],
        }
    }
    /// All values as f32.
    pub fn to_f32_vec(&self) -> Vec<f32> {
        match &self.data {
            ColumnData::F32(v) => v.clone(),
            ColumnData::F64(v) => v.iter().map(|&x| x as f32).collect(),
        }
    }
    /// Number of values.
    pub fn len(&self) -> usize {
        match &self.data {
            ColumnData::F32(v) => v.len(),
            ColumnData::F64(v) => v.len(),
        }
    }
    /// True when the column holds no value.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// True for the PLY integer types.
    pub fn is_integer(&self) -> bool {
        !matches!(self.scalar, ScalarType::Float | ScalarType::Double)
    }
}

/// One PLY element (e.g. `vertex`, `chunk`, `sh`) with its scalar properties as columns.
#[derive(Debug, Clone)]
pub struct Table {
    /// Element name.
    pub name: String,
    /// Number of rows.
    pub count: usize,
    /// Scalar properties in header order (list properties are not kept).
    pub columns: Vec<Column>,
}

impl Table {
    /// The column called `name`, if any.
    pub fn column(&self, name: &str) -> Option<&Column> {
        self.columns.iter().find(|c| c.name == name)
    }

    /// The column called `name`, or an error naming the element and property.
    pub fn require(&self, name: &str, path: &Path) -> Result<&Column> {
        self.column(name).ok_or_else(|| {
            SceneError::malformed(
                path,
                format!("element '{}' has no property '{name}'", self.name),
            )
        })
    }
}

/// A parsed PLY file: its encoding, comments and elements.
#[derive(Debug, Clone)]
pub struct PlyFile {
    /// Payload encoding.
    pub encoding: Encoding,
    /// Header comments.
    pub comments: Vec<String>,
    /// Elements in file order.
    pub tables: Vec<Table>,
}

impl PlyFile {
    /// The element called `name`, if any.
    pub fn table(&self, name: &str) -> Option<&Table> {
        self.tables.iter().find(|t| t.name == name)
    }
}

/// Parses a whole PLY file held in memory.
///
/// Strict where a lenient reader would shift columns or drop data silently: a property or
/// element declared twice, an ASCII row with more or fewer values than its properties, and data
/// holding whole rows beyond an element's declared count are errors naming the line or element;
/// other bytes after the last element are a warning.
pub fn read_ply_tables(bytes: &[u8], path: &Path) -> Result<PlyFile> {
    let header_lines = check_header_names(bytes, path)?;
    let parser = Parser::<Row>::new();
    let mut reader = Reader::new(Cursor::new(bytes));
    let header: Header = parser
        .read_header(&mut reader)
        .map_err(|e| SceneError::malformed(path, format!("bad PLY header: {e}")))?;
    // 1.0 is the only PLY version there is: another is a file this reader cannot vouch for.
    if header.version.major != 1 || header.version.minor != 0 {
        return Err(SceneError::malformed(
            path,
            format!(
                "PLY header: format version {}.{} (only 1.0 exists)",
                header.version.major, header.version.minor
            ),
        ));
    }
    let mut tables = Vec::with_capacity(header.elements.len());
    let mut line = header_lines;
    for def in header.elements.values() {
        tables.push(read_element(
            &parser,
            &mut reader,
            &header,
            def,
            (path, line),
        )?);
        line += def.count;
    }
    let rest = &bytes[(reader.get_ref().position() as usize).min(bytes.len())..];
    if let Some(last) = header.elements.values().last() {
        check_trailing(rest, header.encoding, last, path)?;
    }
    Ok(PlyFile {
        encoding: header.encoding,
        comments: header.comments.clone(),
        tables,
    })
}

/// Refuses a header that declares an element, or a property of one element, twice (the PLY
/// parser keys them by name and would read shifted columns); returns the header's line count.
fn check_header_names(bytes: &[u8], path: &Path) -> Result<usize> {
    let head = &bytes[..bytes.len().min(MAX_HEADER_BYTES)];
    let Some(end) = head
        .windows(b"end_header".len())
        .position(|w| w == b"end_header")
    else {
        // Checking a cut header would misreport its last, cut line.
        return Err(SceneError::malformed(
            path,
            if bytes.len() > MAX_HEADER_BYTES {
                format!(
                    "no `end_header` in the first {MAX_HEADER_BYTES} bytes: the header is \
                     longer than splatraj reads (too many properties or comments)"
                )
            } else {
                "the PLY header has no `end_header` line".to_string()
            },
        ));
    };
    let text = String::from_utf8_lossy(&head[..end]);
    let mut elements: Vec<(String, usize)> = Vec::new();
    let mut properties: Vec<(String, usize)> = Vec::new();
    let mut lines = 0;
    for (number, line) in text.lines().enumerate().map(|(i, l)| (i + 1, l)) {
        lines = number;
        let words: Vec<&str> = line.split_whitespace().collect();
        let (keyword, name) = match words.as_slice() {
            ["element", name, ..] => ("element", *name),
            ["property", .., name] => ("property", *name),
            _ => continue,
        };
        let owner = match elements.last() {
            Some((e, _)) if keyword == "property" => format!(" of element '{e}'"),
            _ => String::new(),
        };
        let seen = if keyword == "element" {
            properties.clear();
            &mut elements
        } else {
            &mut properties
        };
        if let Some((_, first)) = seen.iter().find(|(n, _)| n == name) {
            return Err(SceneError::malformed(
                path,
                format!(
                    "header line {number}: {keyword} '{name}'{owner} is declared twice (first on \
                     line {first}); every name must be unique"
                ),
            ));
        }
        seen.push((name.to_string(), number));
    }
    // The `end_header` line itself.
    Ok(lines + 1)
}

/// Bytes after the last element: whole rows of it are a count that disagrees with the data
/// (an error), anything else but whitespace a warning.
fn check_trailing(rest: &[u8], encoding: Encoding, last: &ElementDef, path: &Path) -> Result<()> {
    let more_rows = |rows: String| {
        SceneError::malformed(
            path,
            format!(
                "the data holds {rows} more rows of element '{}' than its header count {} \
                 declares; fix the count in the header",
                last.name, last.count
            ),
        )
    };
    match encoding {
        Encoding::Ascii => {
            let text = String::from_utf8_lossy(rest);
            let extra: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
            if extra.is_empty() {
                return Ok(());
            }
            let widths_fit = extra.iter().all(|l| {
                expected_tokens(&l.split_whitespace().collect::<Vec<_>>(), last).is_some()
            });
            if widths_fit {
                return Err(more_rows(extra.len().to_string()));
            }
            tracing::warn!(
                "{}: {} lines after the last element are not part of the file's data and are \
                 ignored",
                path.display(),
                extra.len()
            );
        }
        Encoding::BinaryLittleEndian | Encoding::BinaryBigEndian => {
            if rest.is_empty() {
                return Ok(());
            }
            match binary_row_size(last) {
                Some(size) if size > 0 && rest.len().is_multiple_of(size) => {
                    return Err(more_rows((rest.len() / size).to_string()));
                }
                _ => tracing::warn!(
                    "{}: {} bytes after the last element ('{}') are ignored",
                    path.display(),
                    rest.len(),
                    last.name
                ),
            }
        }
    }
    Ok(())
}

/// Bytes of one binary row of `def` (None with list properties: rows vary).
fn binary_row_size(def: &ElementDef) -> Option<usize> {
    def.properties
        .values()
        .map(|p| match &p.data_type {
            PropertyType::Scalar(s) => Some(scalar_size(s)),
            PropertyType::List(..) => None,
        })
        .sum()
}

fn scalar_size(scalar: &ScalarType) -> usize {
    match scalar {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    }
}

/// The number of values an ASCII row of `def` holds when it starts with `tokens` (list
/// lengths read from the row), if the row has exactly that many.
fn expected_tokens(tokens: &[&str], def: &ElementDef) -> Option<usize> {
    let mut at = 0usize;
    for p in def.properties.values() {
        match &p.data_type {
            PropertyType::Scalar(_) => at += 1,
            PropertyType::List(..) => {
                let len: usize = tokens.get(at)?.parse().ok()?;
                at = at.checked_add(1 + len)?;
            }
        }
    }
    (at == tokens.len()).then_some(at)
}

fn read_element(
    parser: &Parser<Row>,
    reader: &mut Reader<Cursor<&[u8]>>,
    header: &Header,
    def: &ElementDef,
    (path, first_line): (&Path, usize),
) -> Result<Table> {
    let scalars: Vec<(String, ScalarType)> = def
        .properties
        .values()
        .filter_map(|p| match &p.data_type {
            PropertyType::Scalar(s) => Some((p.name.clone(), s.clone())),
            PropertyType::List(..) => None,
        })
        .collect();
    // Cap the up-front allocation by the rows the rest of the file can hold: a corrupt header
    // may claim billions of rows, or a hundred thousand properties. (A binary row takes its
    // size; an ASCII value at least a digit and a separator.)
    let left = reader
        .get_ref()
        .get_ref()
        .len()
        .saturating_sub(reader.get_ref().position() as usize);
    let row_bytes = binary_row_size(def)
        .filter(|_| header.encoding != Encoding::Ascii)
        .unwrap_or(2 * def.properties.len())
        .max(1);
    let capacity = def.count.min(left / row_bytes);
    let mut columns: Vec<Column> = scalars
        .iter()
        .map(|(name, scalar)| Column {
            name: name.clone(),
            scalar: scalar.clone(),
            data: match scalar {
                ScalarType::Float => ColumnData::F32(Vec::with_capacity(capacity)),
                _ => ColumnData::F64(Vec::with_capacity(capacity)),
            },
        })
        .collect();

    let mut line = String::new();
    for i in 0..def.count {
        let row = match header.encoding {
            Encoding::Ascii => {
                line.clear();
                let read = reader
                    .get_mut()
                    .read_line(&mut line)
                    .map_err(|e| SceneError::io(path, e))?;
                if read == 0 {
                    return Err(truncated(path, def, i));
                }
                let tokens: Vec<&str> = line.split_whitespace().collect();
                if expected_tokens(&tokens, def).is_none() {
                    return Err(SceneError::malformed(
                        path,
                        format!(
                            "line {}: element '{}' row {i} holds {} values, its {} properties \
                             need {}",
                            first_line + i + 1,
                            def.name,
                            tokens.len(),
                            def.properties.len(),
                            if binary_row_size(def).is_some() {
                                def.properties.len().to_string()
                            } else {
                                "a different number (with the list lengths it gives)".to_string()
                            }
                        ),
                    ));
                }
                parser.read_ascii_element(line.trim(), def)
            }
            Encoding::BinaryLittleEndian => {
                parser.read_little_endian_element(reader.get_mut(), def)
            }
            Encoding::BinaryBigEndian => parser.read_big_endian_element(reader.get_mut(), def),
        };
        let row = row.map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                truncated(path, def, i)
            } else {
                SceneError::malformed(path, format!("element '{}' row {i}: {e}", def.name))
            }
        })?;
        if row.0.len() != columns.len() {
            return Err(SceneError::malformed(
                path,
                format!(
                    "element '{}' row {i}: {} scalar values for {} properties",
                    def.name,
                    row.0.len(),
                    columns.len()
                ),
            ));
        }
        for (column, value) in columns.iter_mut().zip(row.0) {
            match &mut column.data {
                ColumnData::F32(v) => v.push(value as f32),
                ColumnData::F64(v) => v.push(value),
            }
        }
    }
    Ok(Table {
        name: def.name.clone(),
        count: def.count,
        columns,
    })
}

fn truncated(path: &Path, def: &ElementDef, row: usize) -> SceneError {
    SceneError::malformed(
        path,
        format!(
            "file is truncated: element '{}' declares {} rows but the data ends at row {row}",
            def.name, def.count
        ),
    )
}
