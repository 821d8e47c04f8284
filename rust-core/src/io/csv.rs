//! Text columns: `.csv` with a header row of names, and `.xyz` with bare numbers.
//!
//! CSV files come from many tools (ParaView writes `Points:0`, pandas `position_0`, hand-made
//! ones `x`), so column names are matched forgivingly: `x,y,z` in any case or a 3-column group
//! called position/points/pos become positions, and any other group `name_0..`, `name:0..`,
//! `name[0]..` or `name_x/_y/_z` becomes one multi-component attribute.

use super::numeric::{parse_number, show};
use crate::error::{Error, Result};
use crate::field::particles::{Attribute, ParticleData};

/// Names a 3-component group may have to be taken as positions (compared in lower case).
const POSITION_GROUPS: &[&str] = &[
    "position",
    "positions",
    "points",
    "point",
    "pos",
    "p",
    "coordinates",
    "coords",
];

/// Reads a CSV file with a header row (separator: comma, semicolon or tab, whichever the
/// header uses). A file whose first row is all numbers is read like XYZ.
pub(crate) fn read_csv(bytes: &[u8], name: &str) -> Result<ParticleData> {
    let text = String::from_utf8_lossy(bytes);
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let Some((_, header)) = lines.next() else {
        return Err(Error::format(name, "no header row (the file has no data)"));
    };
    let separator = [',', ';', '\t'].into_iter().find(|&s| header.contains(s));
    let split = |line: &'_ str| -> Vec<String> {
        match separator {
            Some(s) => line.split(s).map(|f| unquote(f).to_string()).collect(),
            None => line
                .split_whitespace()
                .map(|f| unquote(f).to_string())
                .collect(),
        }
    };
    let names = split(header);
    if names.iter().all(|n| parse_number(n.as_bytes()).is_some()) {
        return read_xyz(bytes, name);
    }
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    for (line_no, line) in lines {
        let fields = split(line);
        if fields.len() != names.len() {
            return Err(Error::format(
                name,
                format!(
                    "line {}: {} fields, but the header names {}",
                    line_no + 1,
                    fields.len(),
                    names.len()
                ),
            ));
        }
        for ((field, column), col_name) in fields.iter().zip(&mut columns).zip(&names) {
            let v = parse_number(field.as_bytes()).ok_or_else(|| {
                Error::format(
                    name,
                    format!(
                        "line {}: column '{col_name}' holds '{}', not a number",
                        line_no + 1,
                        show(field.as_bytes())
                    ),
                )
            })?;
            column.push(v);
        }
    }
    assemble(&names, columns, name)
}

/// Reads whitespace- (or comma-) separated rows: the first three columns are positions, the
/// others scalar attributes `col3`, `col4`, ... Text after `#` is a comment.
pub(crate) fn read_xyz(bytes: &[u8], name: &str) -> Result<ParticleData> {
    let text = String::from_utf8_lossy(bytes);
    let mut columns: Vec<Vec<f64>> = Vec::new();
    for (line_no, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("");
        let fields: Vec<&str> = line
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|f| !f.is_empty())
            .collect();
        if fields.is_empty() {
            continue;
        }
        if columns.is_empty() {
            if fields.len() < 3 {
                return Err(Error::format(
                    name,
                    format!(
                        "line {}: {} columns, but x y z need at least 3",
                        line_no + 1,
                        fields.len()
                    ),
                ));
            }
            columns = vec![Vec::new(); fields.len()];
        }
        if fields.len() != columns.len() {
            return Err(Error::format(
                name,
                format!(
                    "line {}: {} columns, but the first row has {}",
                    line_no + 1,
                    fields.len(),
                    columns.len()
                ),
            ));
        }
        for (k, (f, column)) in fields.iter().zip(&mut columns).enumerate() {
            column.push(parse_number(f.as_bytes()).ok_or_else(|| {
                Error::format(
                    name,
                    format!(
                        "line {}: column {} holds '{}', not a number",
                        line_no + 1,
                        k + 1,
                        show(f.as_bytes())
                    ),
                )
            })?);
        }
    }
    if columns.is_empty() {
        return Err(Error::format(name, "no data rows"));
    }
    let mut columns = columns.into_iter();
    let (x, y, z) = (
        columns.next().unwrap_or_default(),
        columns.next().unwrap_or_default(),
        columns.next().unwrap_or_default(),
    );
    Ok(ParticleData {
        positions: zip_xyz(&x, &y, &z),
        attributes: columns
            .enumerate()
            .map(|(k, c)| Attribute::scalar(format!("col{}", k + 3), c))
            .collect(),
        ..Default::default()
    })
}

fn unquote(field: &str) -> &str {
    let f = field.trim();
    f.strip_prefix('"')
        .and_then(|f| f.strip_suffix('"'))
        .or_else(|| f.strip_prefix('\'').and_then(|f| f.strip_suffix('\'')))
        .unwrap_or(f)
        .trim()
}

fn zip_xyz(x: &[f64], y: &[f64], z: &[f64]) -> Vec<glam::DVec3> {
    x.iter()
        .zip(y)
        .zip(z)
        .map(|((&x, &y), &z)| glam::DVec3::new(x, y, z))
        .collect()
}

/// Splits a column name into a group name and component index: `v_0`, `v:1`, `v[2]`,
/// `v_x`, `v.y`.
fn component_of(name: &str) -> Option<(&str, usize)> {
    if let Some(inner) = name.strip_suffix(']') {
        let (base, index) = inner.rsplit_once('[')?;
        return Some((base, index.trim().parse().ok()?));
    }
    let (base, suffix) = name.rsplit_once(['_', ':', '.'])?;
    if base.is_empty() {
        return None;
    }
    let index = match suffix {
        "x" | "X" => 0,
        "y" | "Y" => 1,
        "z" | "Z" => 2,
        digits => digits.parse().ok()?,
    };
    Some((base, index))
}

/// A column group: the columns holding components 0, 1, ... of one array.
struct Group {
    name: String,
    columns: Vec<usize>,
}

/// Groups columns into arrays, picks the positions and turns the rest into attributes.
fn assemble(names: &[String], columns: Vec<Vec<f64>>, file: &str) -> Result<ParticleData> {
    let mut groups: Vec<Group> = Vec::new();
    let mut grouped = vec![false; names.len()];
    for (i, n) in names.iter().enumerate() {
        let Some((base, 0)) = component_of(n) else {
            continue;
        };
        // Collect base+1, base+2, ... written with the same separator style.
        let mut members = vec![i];
        for k in 1.. {
            let next = names.iter().position(|m| {
                component_of(m).is_some_and(|(b, c)| b == base && c == k) && same_style(n, m)
            });
            match next {
                Some(j) => members.push(j),
                None => break,
            }
        }
        if members.len() >= 2 && members.iter().all(|&j| !grouped[j]) {
            members.iter().for_each(|&j| grouped[j] = true);
            groups.push(Group {
                name: base.to_string(),
                columns: members,
            });
        }
    }

    let find_scalar = |axis: &str| {
        names
            .iter()
            .position(|n| n.eq_ignore_ascii_case(axis))
            .filter(|&i| !grouped[i])
    };
    let position_columns = match (find_scalar("x"), find_scalar("y"), find_scalar("z")) {
        (Some(x), Some(y), Some(z)) => vec![x, y, z],
        _ => {
            let g = groups
                .iter()
                .position(|g| {
                    g.columns.len() == 3
                        && POSITION_GROUPS.contains(&g.name.to_ascii_lowercase().as_str())
                })
                .ok_or_else(|| {
                    Error::format(
                        file,
                        format!(
                            "no position columns: expected x,y,z (or X,Y,Z, position_0..2, Points:0..2); the columns are {}",
                            names.join(", ")
                        ),
                    )
                })?;
            groups.remove(g).columns
        }
    };

    let positions = zip_xyz(
        &columns[position_columns[0]],
        &columns[position_columns[1]],
        &columns[position_columns[2]],
    );
    let rows = positions.len();
    // Attributes in the order their first column appears.
    let mut attributes: Vec<(usize, Attribute)> = Vec::new();
    for g in groups {
        let k = g.columns.len();
        let data = (0..rows)
            .flat_map(|r| g.columns.iter().map(move |&c| (c, r)))
            .map(|(c, r)| columns[c][r])
            .collect();
        attributes.push((
            g.columns[0],
            Attribute {
                name: g.name,
                components: k,
                data,
            },
        ));
    }
    for (i, n) in names.iter().enumerate() {
        if !grouped[i] && !position_columns.contains(&i) {
            attributes.push((i, Attribute::scalar(n.clone(), columns[i].clone())));
        }
    }
    attributes.sort_by_key(|(i, _)| *i);
    Ok(ParticleData {
        positions,
        attributes: attributes.into_iter().map(|(_, a)| a).collect(),
        ..Default::default()
    })
}

/// Components of one group use one separator and one index style (`v_0, v_1` or `v_x, v_y`),
/// so that `v_x` is not paired with `v:1`.
fn same_style(a: &str, b: &str) -> bool {
    let style = |s: &str| {
        let sep = s.chars().rev().find(|c| matches!(c, '_' | ':' | '.' | '['));
        let letter = s.chars().last().is_some_and(|c| c.is_ascii_alphabetic());
        (sep, letter)
    };
    style(a) == style(b)
}

#[cfg(test)]
mod tests {
    use super::super::read_particles_from_bytes;
    use super::super::test_support::assert_no_cut_panics;
    use super::*;

    fn csv(s: &str) -> Result<ParticleData> {
        read_particles_from_bytes(s.as_bytes(), "csv", "t.csv")
    }

    #[test]
    fn plain_xyz_columns_and_scalars() {
        let p = csv("x,y,z,density\n1,2,3,1000\n4,5,6,999.5\n").unwrap();
        assert_eq!(p.positions[1].to_array(), [4.0, 5.0, 6.0]);
        assert_eq!(p.require("density").unwrap().data, vec![1000.0, 999.5]);
    }

    #[test]
    fn paraview_and_pandas_style_groups() {
        let p = csv("\"velocity:0\",\"velocity:1\",\"velocity:2\",\"rho\",\"Points:0\",\"Points:1\",\"Points:2\"\n1,2,3,7,0.5,0.25,0.125\n")
            .unwrap();
        assert_eq!(p.positions[0].to_array(), [0.5, 0.25, 0.125]);
        let v = p.require("velocity").unwrap();
        assert_eq!((v.components, v.data.clone()), (3, vec![1.0, 2.0, 3.0]));
        assert_eq!(p.attributes[1].name, "rho");

        let p = csv("id;position_0;position_1;position_2;v_x;v_y;v_z\n3;1;2;3;4;5;6\n").unwrap();
        assert_eq!(p.positions[0].to_array(), [1.0, 2.0, 3.0]);
        assert_eq!(p.require("v").unwrap().data, vec![4.0, 5.0, 6.0]);
        assert_eq!(p.require("id").unwrap().components, 1);

        let p = csv("X\tY\tZ\tn[0]\tn[1]\n1\t2\t3\t4\t5\n").unwrap();
        assert_eq!(p.require("n").unwrap().components, 2);
    }

    #[test]
    fn errors_say_what_is_missing() {
        let e = csv("a,b,c\n1,2,3\n").unwrap_err().to_string();
        assert!(
            e.contains("t.csv: no position columns") && e.contains("a, b, c"),
            "{e}"
        );
        let e = csv("x,y,z\n1,2,3\n4,5\n").unwrap_err().to_string();
        assert!(e.contains("line 3: 2 fields"), "{e}");
        let e = csv("x,y,z\n1,2,abc\n").unwrap_err().to_string();
        assert!(e.contains("column 'z' holds 'abc'"), "{e}");
        assert!(csv("\n\n").is_err());
        assert!(csv("x,y,z\n").unwrap().is_empty());
    }

    #[test]
    fn xyz_with_comments_and_extra_columns() {
        let f = b"# exported\n1 2 3 0.5\n4 5 6 0.25 # last\n\n";
        let p = read_particles_from_bytes(f, "xyz", "t.xyz").unwrap();
        assert_eq!(p.len(), 2);
        assert_eq!(p.require("col3").unwrap().data, vec![0.5, 0.25]);
        let e = read_particles_from_bytes(b"1 2\n", "xyz", "t.xyz").unwrap_err();
        assert!(e.to_string().contains("at least 3"), "{e}");
        let e = read_particles_from_bytes(b"1 2 3\n1 2 3 4\n", "xyz", "t.xyz").unwrap_err();
        assert!(e.to_string().contains("line 2: 4 columns"), "{e}");
        // A CSV without a header reads like XYZ.
        let p = csv("1,2,3\n4,5,6\n").unwrap();
        assert_eq!(p.len(), 2);
    }

    #[test]
    fn no_cut_or_garbage_panics() {
        let f = "x,y,z,v_0,v_1,v_2\n1,2,3,4,5,6\n1.5,2.5,3.5,4.5,5.5,6.5\n".repeat(20);
        assert_no_cut_panics(f.as_bytes(), "csv", "c.csv");
        assert_no_cut_panics(b"1 2 3 4\n5 6 7 8\n9 1 2 3\n", "xyz", "c.xyz");
        let garbage: Vec<u8> = (0..=255u8).cycle().take(3000).collect();
        assert!(read_particles_from_bytes(&garbage, "csv", "g.csv").is_err());
        assert!(read_particles_from_bytes(&garbage, "xyz", "g.xyz").is_err());
    }
}
