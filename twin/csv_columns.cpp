// twin layer — CSV records by column (see csv_columns.hpp).
#include "twin/csv_columns.hpp"

#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace omnitwin::twin {

const std::vector<double>& CsvColumns::column(const std::string& name) const {
  for (std::size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) return columns[i];
  throw std::runtime_error(file + " has no column " + name);
}

CsvColumns read_csv_columns(const std::string& path) {
  CsvColumns t;
  t.file = path;
  std::ifstream in(path);
  std::string line;
  if (!in || !std::getline(in, line)) throw std::runtime_error("cannot read " + path);
  for (std::stringstream hs(line); std::getline(hs, line, ',');) t.names.push_back(line);
  t.columns.resize(t.names.size());
  while (std::getline(in, line)) {
    std::stringstream ls(line);
    std::string cell;
    for (std::size_t c = 0; c < t.names.size(); ++c) {
      if (!std::getline(ls, cell, ',')) cell.clear();
      char* end = nullptr;
      const double v = std::strtod(cell.c_str(), &end);
      t.columns[c].push_back(end != cell.c_str() ? v : std::numeric_limits<double>::quiet_NaN());
    }
  }
  return t;
}

}  // namespace omnitwin::twin
