//! Columns of a row-major float table (the body of a binary PLY, a block of rows at a time),
//! gathered in a chosen order into another table: one pass over each row while it is in cache,
//! rows in parallel. NumPy's column gathers go element by element across the rows instead.

use rayon::prelude::*;

use crate::SizeError;

/// Rows per parallel task.
const ROWS_PER_TASK: usize = 4096;

/// Copies, for each row of `table` (`width` values a row), its values at `columns` in that order
/// into the same row of `out` (`columns.len()` values a row).
pub fn gather_columns(table: &[f32], width: usize, columns: &[usize], out: &mut [f32]) -> Result<(), SizeError> {
    let picked = columns.len();
    if width == 0 || !table.len().is_multiple_of(width) {
        return Err(SizeError {
            name: "table",
            expected: table.len().next_multiple_of(width.max(1)),
            got: table.len(),
        });
    }
    let rows = table.len() / width;
    if out.len() != rows * picked {
        return Err(SizeError { name: "out", expected: rows * picked, got: out.len() });
    }
    if let Some(&column) = columns.iter().find(|&&c| c >= width) {
        return Err(SizeError { name: "columns", expected: width, got: column + 1 });
    }
    if picked == 0 {
        return Ok(());
    }
    out.par_chunks_mut(picked).zip(table.par_chunks(width)).with_min_len(ROWS_PER_TASK).for_each(|(to, from)| {
        for (value, &column) in to.iter_mut().zip(columns) {
            *value = from[column];
        }
    });
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn rows_keep_their_order_and_columns_come_as_asked() {
        let (rows, width) = (10_000, 7);
        let table: Vec<f32> = (0..rows * width).map(|i| i as f32).collect();
        let columns = [6, 0, 3, 3];
        let mut out = vec![0.0; rows * columns.len()];
        gather_columns(&table, width, &columns, &mut out).unwrap();
        for r in [0, 1, 4095, 4096, rows - 1] {
            let want: Vec<f32> = columns.iter().map(|&c| (r * width + c) as f32).collect();
            assert_eq!(out[r * 4..r * 4 + 4], want[..]);
        }
        assert!(gather_columns(&table, width, &[7], &mut vec![0.0; rows]).is_err());
        assert!(gather_columns(&table, width, &[0], &mut vec![0.0; rows - 1]).is_err());
        assert!(gather_columns(&table[1..], width, &[0], &mut vec![0.0; rows]).is_err());
    }
}
