// twin layer — reading a run's numeric CSV records (trajectory.csv, bus.csv) back by column,
// for commands that work on a recorded run (replay, the thesis-platform experiment).
// Not real-time code: reads the whole file.
#pragma once

#include <string>
#include <vector>

namespace omnitwin::twin {

struct CsvColumns {
  std::vector<std::string> names;             // the header
  std::vector<std::vector<double>> columns;   // one vector per name, one value per row

  // The column called `name`; throws std::runtime_error naming the file and the column.
  const std::vector<double>& column(const std::string& name) const;
  std::size_t rows() const { return columns.empty() ? 0 : columns.front().size(); }
  std::string file;
};

// Reads a header line and rows of numbers (an empty cell or text reads as NaN). Throws
// std::runtime_error naming the file when it cannot be read or has no header.
CsvColumns read_csv_columns(const std::string& path);

}  // namespace omnitwin::twin
