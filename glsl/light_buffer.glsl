// A light-buffer entry's part of its cell (glsl/layout.h, MOBIRT_LIGHT_BUFFER_SUBCELLS): whether
// column sx, row sy of the cell lies in it. The part is x0 + S y0 + S^2 (x1 + S y1), an exact
// integer below 2^24 in a float; its fields come back by products with powers of two (exact: a
// product is correctly rounded where a division need not be, and a part of 2^24 - 1 sits one ulp
// below a multiple of S^2) and floors. The CPU's twin is light_buffer_sub_contains
// (src/accel/light_buffer.h); tests/numerics_test.cpp runs both on the same parts.
bool light_buffer_part_contains(float part, float sx, float sy) {
  const float S = float(MOBIRT_LIGHT_BUFFER_SUBCELLS);
  const float inv_s = 1.0 / S;
  float hi = floor(part * (inv_s * inv_s));  // x1 + S y1
  float lo = part - hi * (S * S);            // x0 + S y0
  float y0 = floor(lo * inv_s);
  float y1 = floor(hi * inv_s);
  return sx >= lo - y0 * S && sx <= hi - y1 * S && sy >= y0 && sy <= y1;
}
