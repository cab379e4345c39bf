// Twin: addon/world_spots.py (the functions that read no table; the rest read spot_datum).
// Microfacet Lab: a world spot's own texels (addon/lamps.py SpotTexels, from offset o of the
// generated spot_datum table): the radiance the shaders predict from them (nee.h), and
// directions drawn over them in proportion to their light (lamps.h sample_lamp), as Cycles'
// world importance map does, where a uniform cone around a pixelated disc wastes its corners.
#ifndef MFL_SPOTS_H
#define MFL_SPOTS_H

#if MFL_SPOT_TEXELS
// Texel (ix, iy) of the world spot whose texels start at o (addon/lamps.py SpotTexels): columns
// wrap around the image, rows stop at its edges (the box holds no pole); 0 outside the box.
// index receives the texel's place in the box (row by row), -1 outside it.
color spot_texel_index(int o, int ix, int iy, output int index)
{
    index = -1;
    int width = int(spot_datum(o));
    int c = ix - int(spot_datum(o + 2));
    int r = clamp(iy, 0, int(spot_datum(o + 1)) - 1) - int(spot_datum(o + 3));
    c = ((c % width) + width) % width;
    int cols = int(spot_datum(o + 4));
    if (c >= cols || r < 0 || r >= int(spot_datum(o + 5)))
        return color(0.0);
    index = r * cols + c;
    int k = o + MFL_SPOT_HEADER + 3 * index;
    return color(spot_datum(k), spot_datum(k + 1), spot_datum(k + 2));
}

color spot_texel(int o, int ix, int iy)
{
    int index;
    return spot_texel_index(o, ix, iy, index);
}

// Where the spot's image reads the direction dir, in pixels (x, y), as Cycles' equirectangular
// Environment Texture: lookup direction d = R dir, u = 1/2 - atan2(d_y, d_x) / 2 pi, v = 1/2 +
// atan2(d_z, hypot(d_x, d_y)) / pi, written as Cycles' own OSL node writes it (OSL's trig is
// approximate: acos(d_z) in place of the atan2 read 5e-4 off in Linear).
void spot_pixel(int o, vector dir, output float x, output float y)
{
    vector d = vector(dot(vector(spot_datum(o + 7), spot_datum(o + 8), spot_datum(o + 9)), dir),
                      dot(vector(spot_datum(o + 10), spot_datum(o + 11), spot_datum(o + 12)), dir),
                      dot(vector(spot_datum(o + 13), spot_datum(o + 14), spot_datum(o + 15)), dir));
    x = (-atan2(d[1], d[0]) / M_2PI + 0.5) * spot_datum(o);
    y = (atan2(d[2], hypot(d[0], d[1])) / M_PI + 0.5) * spot_datum(o + 1);
}

// A world spot's radiance toward dir, read from its texels at (x, y) as Cycles reads the image,
// Closest or Linear (Cycles' interp_closest, interp_linear: texel centres at half-integers).
color spot_radiance(int o, vector dir)
{
    float x, y;
    spot_pixel(o, dir, x, y);
    if (spot_datum(o + 6) < 0.5)
        return spot_texel(o, int(floor(x)), int(floor(y)));
    float fx = x - 0.5 - floor(x - 0.5);
    float fy = y - 0.5 - floor(y - 0.5);
    int ix = int(floor(x - 0.5));
    int iy = int(floor(y - 0.5));
    return (1.0 - fy) * ((1.0 - fx) * spot_texel(o, ix, iy) + fx * spot_texel(o, ix + 1, iy)) +
           fy * ((1.0 - fx) * spot_texel(o, ix, iy + 1) + fx * spot_texel(o, ix + 1, iy + 1));
}

// sin(latitude) at the bottom edge of image row y (row 0 at the bottom).
float spot_sin_latitude(int o, float y) { return sin((y / spot_datum(o + 1) - 0.5) * M_PI); }

// The solid angle of one texel of image row iy: (2 pi / W) (sin lat_top - sin lat_bottom).
float spot_texel_solid_angle(int o, int iy)
{
    return M_2PI / spot_datum(o) * (spot_sin_latitude(o, float(iy + 1)) -
                                    spot_sin_latitude(o, float(iy)));
}

// The cumulative share of texels 0..t of the box in the spot's sampling (addon/lamps.py
// SpotTexels.cumulative: luminance, spread over its neighbours for Linear, times solid angle).
float spot_cumulative(int o, int t)
{
    if (t < 0)
        return 0.0;
    int n = int(spot_datum(o + 4)) * int(spot_datum(o + 5));
    return spot_datum(o + MFL_SPOT_HEADER + 3 * n + t);
}

// A direction (world space) over the spot's texels: texel t with its share, chosen by u1 (a
// binary search of the cumulative shares), then uniform over its solid angle: u1's place within
// the share across the texel's columns, u2 uniform in sin(latitude) across its row.
vector spot_sample(int o, float u1, float u2)
{
    int cols = int(spot_datum(o + 4));
    int lo = 0;
    int hi = cols * int(spot_datum(o + 5)) - 1;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (u1 < spot_cumulative(o, mid))
            hi = mid;
        else
            lo = mid + 1;
    }
    float before = spot_cumulative(o, lo - 1);
    float share = spot_cumulative(o, lo) - before;
    float fx = (share > 0.0) ? clamp((u1 - before) / share, 0.0, 1.0) : 0.5;
    int r = lo / cols;
    float x = spot_datum(o + 2) + float(lo - r * cols) + fx;
    float y = spot_datum(o + 3) + float(r);
    float sl = mix(spot_sin_latitude(o, y), spot_sin_latitude(o, y + 1.0), u2);
    float cl = sqrt(max(1.0 - sl * sl, 0.0));
    float phi = (0.5 - x / spot_datum(o)) * M_2PI;
    vector d = vector(cl * cos(phi), cl * sin(phi), sl);
    // dir = R^T d: R's rows are the slots 7-15.
    return d[0] * vector(spot_datum(o + 7), spot_datum(o + 8), spot_datum(o + 9)) +
           d[1] * vector(spot_datum(o + 10), spot_datum(o + 11), spot_datum(o + 12)) +
           d[2] * vector(spot_datum(o + 13), spot_datum(o + 14), spot_datum(o + 15));
}

// spot_sample's density over solid angle toward dir: the share of the texel dir falls in over
// that texel's solid angle; 0 outside the box.
float spot_pdf(int o, vector dir)
{
    float x, y;
    spot_pixel(o, dir, x, y);
    int iy = int(floor(y));
    int t;
    spot_texel_index(o, int(floor(x)), iy, t);
    if (t < 0 || iy < 0 || iy >= int(spot_datum(o + 1)))
        return 0.0;
    return (spot_cumulative(o, t) - spot_cumulative(o, t - 1)) / spot_texel_solid_angle(o, iy);
}
#endif

#endif  // MFL_SPOTS_H
